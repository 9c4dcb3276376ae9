"""Render the contact pressure of a run as ParaView shows it (pvpython).

    xvfb-run -a pvpython tools/paraview_contact.py output/cube/cube.xdmf [out.png]

Opens the run's XDMF file as a ParaView user would, takes its grid "contact"
(one point per contact node), triangulates it (Filters > Delaunay 2D, as one
would do by hand) and writes a view from below coloured by contact_pressure
to out.png (default: contact_pressure.png beside the .xdmf). Needs Debian's
python3-paraview (and xvfb for xvfb-run on a machine without a display).
"""
import os
import sys

from paraview.simple import (ColorBy, Delaunay2D, GetActiveViewOrCreate, SaveScreenshot, Show,  # noqa: E402
                             XDMFReader)


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    xdmf = os.path.abspath(sys.argv[1])
    png = sys.argv[2] if len(sys.argv) > 2 else os.path.join(os.path.dirname(xdmf), "contact_pressure.png")
    reader = XDMFReader(FileNames=[xdmf])
    reader.GridStatus = ["contact"]
    reader.UpdatePipeline()
    bounds = reader.GetDataInformation().GetBounds()
    cx, cy = 0.5 * (bounds[0] + bounds[1]), 0.5 * (bounds[2] + bounds[3])
    size = max(bounds[1] - bounds[0], bounds[3] - bounds[2])
    surface = Delaunay2D(Input=reader)
    view = GetActiveViewOrCreate("RenderView")
    view.ViewSize = [800, 700]
    display = Show(surface, view)
    ColorBy(display, ("POINTS", "contact_pressure"))
    display.RescaleTransferFunctionToDataRange(True)
    display.SetScalarBarVisibility(view, True)
    view.CameraPosition = [cx, cy, bounds[4] - 2.5 * size]
    view.CameraFocalPoint = [cx, cy, bounds[4]]
    view.CameraViewUp = [0, 1, 0]
    SaveScreenshot(png, view)
    print("wrote", png)


if __name__ == "__main__":
    main()
