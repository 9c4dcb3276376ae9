"""Render the contact pressure of a run as ParaView shows it (pvpython).

    xvfb-run -a pvpython tools/paraview_contact.py RUN.xdmf [out.png] [--step N]

Opens the run's XDMF file as a ParaView user would (XDMF Reader, every grid
enabled), takes its block "contact" (one point per contact node; Filters >
Extract Block), triangulates it (Filters > Delaunay 2D, as one would do by
hand) and writes a view from below coloured by contact_pressure to out.png
(default: contact_pressure.png beside the .xdmf, contact_pressure_stepN.png
for a step of a history). For a load history's temporal XDMF (<run_name>.xdmf
of &history) `--step N` picks the step (the time on ParaView's slider is the
step number); the default is the step report.json beside the file describes
(the peak of the history), else the last one. Needs Debian's python3-paraview
(and xvfb for xvfb-run on a machine without a display).
"""
import argparse
import json
import os

from paraview.simple import (ColorBy, Delaunay2D, ExtractBlock, GetActiveViewOrCreate, MergeBlocks,  # noqa: E402
                             SaveScreenshot, Show, UpdatePipeline, XDMFReader)


def default_step(xdmf, times):
    """The step report.json beside `xdmf` describes (a history: the peak), else the last time."""
    report = os.path.join(os.path.dirname(xdmf), "report.json")
    if os.path.exists(report):
        with open(report) as f:
            step = json.load(f).get("step")
        if step is not None and float(step) in times:
            return int(step)
    return int(times[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("xdmf")
    ap.add_argument("png", nargs="?")
    ap.add_argument("--step", type=int, help="the step of a load history (default: the peak, report.json step)")
    args = ap.parse_args()
    xdmf = os.path.abspath(args.xdmf)
    reader = XDMFReader(FileNames=[xdmf])
    times = list(reader.TimestepValues)
    step = None
    if times:
        step = args.step if args.step is not None else default_step(xdmf, times)
        if float(step) not in times:
            ap.error("--step %d: the history has steps %d to %d" % (step, times[0], times[-1]))
    elif args.step is not None:
        ap.error("--step: %s is not a load history (no time steps)" % args.xdmf)
    name = "contact_pressure.png" if step is None else "contact_pressure_step%d.png" % step
    png = args.png or os.path.join(os.path.dirname(xdmf), name)
    contact = MergeBlocks(Input=ExtractBlock(Input=reader, Selectors=["/Root/contact"]))
    if step is not None:
        UpdatePipeline(time=float(step), proxy=contact)
    else:
        UpdatePipeline(proxy=contact)
    bounds = contact.GetDataInformation().GetBounds()
    cx, cy = 0.5 * (bounds[0] + bounds[1]), 0.5 * (bounds[2] + bounds[3])
    size = max(bounds[1] - bounds[0], bounds[3] - bounds[2])
    surface = Delaunay2D(Input=contact)
    view = GetActiveViewOrCreate("RenderView")
    view.ViewSize = [800, 700]
    if step is not None:
        view.ViewTime = float(step)
    display = Show(surface, view)
    ColorBy(display, ("POINTS", "contact_pressure"))
    display.RescaleTransferFunctionToDataRange(True)
    display.SetScalarBarVisibility(view, True)
    view.CameraPosition = [cx, cy, bounds[4] - 2.5 * size]
    view.CameraFocalPoint = [cx, cy, bounds[4]]
    view.CameraViewUp = [0, 1, 0]
    SaveScreenshot(png, view)
    print("wrote", png, "" if step is None else "(step %d)" % step)


if __name__ == "__main__":
    main()
