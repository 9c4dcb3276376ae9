"""Check the .h5 + .xdmf pair written by the pFUnit test test_io_hdf5_output.pf, independently of
the Fortran reader: the XDMF parses as XML, every dataset it references exists
in the HDF5 file with the dimensions and number type it states, the grids are
consistent (topology sizes, node/cell attribute lengths), the values are the
known functions of the coordinates, and no temporary file is left.

usage: check_fields.py <directory> <run_name> <nnodes> <nelem> <ncontact>
Run with /usr/bin/python3 (it has numpy and h5py).
"""
import os
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np

failures = []


def check(ok, what):
    if not ok:
        failures.append(what)
        print("FAIL:", what)


def main():
    directory, run = sys.argv[1], sys.argv[2]
    nnodes, nelem, ncontact = (int(a) for a in sys.argv[3:6])
    xdmf_path = os.path.join(directory, run + ".xdmf")
    h5_path = os.path.join(directory, run + ".h5")

    leftovers = [n for n in os.listdir(directory) if n.endswith(".tmp") or n.startswith(".feticontact")]
    check(not leftovers, f"temporary files left in {directory}: {leftovers}")

    root = ET.parse(xdmf_path).getroot()
    check(root.tag == "Xdmf", "root element is Xdmf")
    grids = {g.get("Name"): g for g in root.iter("Grid")}
    check("mesh" in grids, "grid 'mesh' present")
    check(("contact" in grids) == (ncontact > 0), "grid 'contact' present exactly when there are contact nodes")

    datasets = {}
    with h5py.File(h5_path, "r") as h5:
        # every HDF DataItem points at a dataset of the stated shape and type
        for item in root.iter("DataItem"):
            check(item.get("Format") == "HDF", "DataItem format HDF")
            file_name, _, path = item.text.strip().partition(":")
            check(os.path.exists(os.path.join(directory, file_name)), f"{file_name} exists beside the .xdmf")
            check(path in h5, f"dataset {path} exists")
            if path not in h5:
                continue
            dset = h5[path]
            dims = tuple(int(d) for d in item.get("Dimensions").split())
            check(dset.shape == dims, f"{path}: shape {dset.shape} == Dimensions {dims}")
            kind = {"Float": "f", "Int": "i"}[item.get("NumberType")]
            check(dset.dtype.kind == kind and dset.dtype.itemsize == int(item.get("Precision")),
                  f"{path}: dtype {dset.dtype} matches NumberType/Precision")
            datasets[path] = dset[...]

        for name in ("/coordinates", "/displacement", "/connectivity", "/subdomain", "/von_mises",
                     "/contact_coordinates", "/contact_pressure", "/contact_gap"):
            check(name in h5, f"dataset {name} exists in the HDF5 file")
        x = h5["/coordinates"][...]
        u = h5["/displacement"][...]
        conn = h5["/connectivity"][...]
        sub = h5["/subdomain"][...]
        vm = h5["/von_mises"][...]
        cx = h5["/contact_coordinates"][...]
        cp = h5["/contact_pressure"][...]
        cg = h5["/contact_gap"][...]

    # sizes and grid consistency
    check(x.shape == (nnodes, 3) and u.shape == (nnodes, 3), "node datasets are (nnodes, 3)")
    check(conn.shape == (nelem, 8) and sub.shape == (nelem,) and vm.shape == (nelem,), "cell datasets")
    check(cx.shape == (ncontact, 3) and cp.shape == (ncontact,) and cg.shape == (ncontact,), "contact datasets")
    for grid in grids.values():
        topo = grid.find("Topology")
        ncells = int(topo.get("NumberOfElements"))
        per = int(topo.get("NodesPerElement"))
        topo_item = topo.find("DataItem")
        check(np.prod([int(d) for d in topo_item.get("Dimensions").split()]) == ncells * per,
              f"{grid.get('Name')}: topology has NumberOfElements x NodesPerElement entries")
        geom_item = grid.find("Geometry").find("DataItem")
        npoints = int(geom_item.get("Dimensions").split()[0])
        check(grid.find("Geometry").get("GeometryType") == "XYZ", "geometry XYZ")
        conn_values = datasets.get(topo_item.text.strip().partition(":")[2])
        if conn_values is not None and conn_values.size:
            check(conn_values.min() >= 0 and conn_values.max() < npoints, "connectivity indexes the points")
        for attr in grid.findall("Attribute"):
            rows = int(attr.find("DataItem").get("Dimensions").split()[0])
            expected = npoints if attr.get("Center") == "Node" else ncells
            check(rows == expected, f"attribute {attr.get('Name')} has one row per {attr.get('Center')}")
            if attr.get("AttributeType") == "Vector":
                check(attr.find("DataItem").get("Dimensions").split()[1] == "3", "vector attribute has 3 components")
    mesh = grids["mesh"]
    check(mesh.find("Topology").get("TopologyType") == "Hexahedron", "mesh topology Hexahedron")
    names = {a.get("Name"): a for a in mesh.findall("Attribute")}
    check(names.get("displacement") is not None and names["displacement"].get("AttributeType") == "Vector"
          and names["displacement"].get("Center") == "Node", "displacement is a node vector")
    for cell_name in ("subdomain", "von_mises"):
        check(names.get(cell_name) is not None and names[cell_name].get("Center") == "Cell",
              f"{cell_name} is a cell attribute")
    if ncontact > 0:
        contact = grids["contact"]
        check(contact.find("Topology").get("TopologyType") == "Polyvertex", "contact topology Polyvertex")
        cnames = {a.get("Name") for a in contact.findall("Attribute")}
        check(cnames == {"contact_pressure", "contact_gap"}, "contact attributes")

    # values: the known functions of the coordinates (see the Fortran test)
    check(np.array_equal(u[:, 0], x[:, 0] * x[:, 1] + 1) and np.array_equal(u[:, 1], x[:, 1] - 2 * x[:, 2])
          and np.array_equal(u[:, 2], 3 * x[:, 0] + x[:, 2] ** 2), "displacement = f(coordinates)")
    if nelem:
        corners = x[conn]                       # (nelem, 8, 3)
        hx, hy, hz = 0.5, 0.25, 0.125
        unit = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                         [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]) * [hx, hy, hz]
        check(np.allclose(corners - corners[:, :1, :], unit[None], atol=1e-12),
              "every hexahedron in VTK order (bottom counter-clockwise, then top)")
        c = corners.mean(axis=1)
        check(np.allclose(vm, c[:, 0] + 10 * c[:, 1] + 100 * c[:, 2], rtol=1e-13, atol=1e-13),
              "von_mises = g(centroid)")
        check(np.array_equal(sub, 1 + np.floor(c[:, 0] / 1.0).astype(int)), "subdomain = slab of the centroid")
        check(sorted(set(conn.ravel().tolist())) == list(range(nnodes)), "every node is used")
    if ncontact:
        check(np.all(cx[:, 2] == 0), "contact nodes on the bottom face")
        check(np.array_equal(cp, 1 + cx[:, 0] + cx[:, 1] ** 2), "contact_pressure = p(coordinates)")
        check(np.array_equal(cg, 0.5 * cx[:, 0] - cx[:, 1] + 0.25), "contact_gap = g(coordinates)")

    print(f"{run}: {len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
