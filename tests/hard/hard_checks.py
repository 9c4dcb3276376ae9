"""Exact solutions of the `block` family (docs/CASES.md) for the hard cases.

Homogeneous material: u = (nu p x/E, nu p y/E, -p z/E) for any E, nu.
Layered material with nu = 0 (E depends on z only, interfaces on element
faces): u = (0, 0, -p * integral_0^z ds/E(s)), piecewise linear in z, which
Q1 reproduces exactly. The layer moduli follow docs/INPUT.md, &material
variation = 'checkerboard' on box subdomains (I, J, K): E for I+J+K even,
contrast*E for odd; with nsub = (1, 1, Nz) that is E_K = E * contrast**(K mod 2).
Everything here is derived from the input, never from the program's output.
"""
import os

import h5py
import numpy as np


def _value(groups, g, v, default):
    for name, value in groups.get(g, []):
        if name == v:
            return value
    return default


def _real(text):
    return float(str(text).lower().replace("d", "e"))


def _ints(text):
    return [int(s) for s in str(text).replace(",", " ").split()]


def layer_moduli(groups):
    """Young's modulus of each of the Nz layers of a nsub = (1, 1, Nz) block."""
    nsub = _ints(_value(groups, "mesh", "nsub", "2, 2, 2"))
    young = _real(_value(groups, "material", "young", "2.1e5"))
    variation = _value(groups, "material", "variation", "'none'").strip("'\"").lower()
    contrast = _real(_value(groups, "material", "contrast", "1"))
    if variation == "none":
        return np.full(nsub[2], young)
    if variation != "checkerboard" or nsub[0] != 1 or nsub[1] != 1:
        raise ValueError("layered exact solution needs variation 'checkerboard' with nsub = 1, 1, Nz")
    return np.array([young * contrast ** (k % 2) for k in range(nsub[2])])


def exact_displacement(groups, x):
    """The exact displacement of the block family at the points x (n, 3)."""
    p = _real(_value(groups, "load", "top_pressure", "0"))
    nu = _real(_value(groups, "material", "poisson", "0.3"))
    variation = _value(groups, "material", "variation", "'none'").strip("'\"").lower()
    if variation == "none":
        young = _real(_value(groups, "material", "young", "2.1e5"))
        return np.column_stack([nu * p * x[:, 0] / young, nu * p * x[:, 1] / young, -p * x[:, 2] / young])
    if nu != 0:
        raise ValueError("no closed-form block solution for a material variation with nu /= 0")
    e = layer_moduli(groups)
    lz = _ints(_value(groups, "mesh", "nsub", "2, 2, 2"))[2]
    lengths = [_real(s) for s in str(_value(groups, "mesh", "lengths", "1, 1, 1")).replace(",", " ").split()]
    t = lengths[2] / lz                                   # layer thickness
    # compliance integral at the layer tops, then linear inside each layer
    tops = np.concatenate([[0.0], np.cumsum(t / e)])
    k = np.clip(np.floor(x[:, 2] / t + 1e-9).astype(int), 0, lz - 1)
    integral = tops[k] + (x[:, 2] - k * t) / e[k]
    return np.column_stack([np.zeros(len(x)), np.zeros(len(x)), -p * integral])


def block_error(outdir, groups):
    """max |u - u_exact| / max |u_exact| over all subdomain copies of all nodes."""
    files = [f for f in os.listdir(outdir) if f.endswith(".h5")]
    if len(files) != 1:
        raise RuntimeError("expected one .h5 file in %s, found %s" % (outdir, files))
    with h5py.File(os.path.join(outdir, files[0]), "r") as h5:
        x = h5["coordinates"][...]
        u = h5["displacement"][...]
    exact = exact_displacement(groups, x)
    return float(np.abs(u - exact).max() / np.abs(exact).max())
