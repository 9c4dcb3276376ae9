#!/usr/bin/python3
"""An undecomposed reference solver of the discrete contact problem, written for the tests.

Independent of every module of the program: the discrete problem is built here
from its definition in docs/CASES.md (the box mesh and its distortion, Q1
trilinear hexahedra with 2x2x2 Gauss points, isotropic elasticity, the
checkerboard of moduli, the top Dirichlet condition and the symmetry planes,
the consistent top pressure load, the obstacle's gap function linearized in z)
and solved as one global problem, without subdomains, by a primal-dual active
set method (Hintermueller, Ito, Kunisch 2002) on the dense stiffness matrix:

    min 1/2 u^T K u - f^T u   s.t.   u_D = value,   -u_z(i) <= g(i) for every contact node i.

Each iteration solves K u = f + lambda with u_z(i) = -g(i) on the active set A
and lambda = 0 elsewhere; the next set is {i : lambda_i - c (u_z(i) + g(i)) > 0}.
It stops when the set repeats, and the result is then the exact solution of the
QP up to the round-off of the dense solve (checked by `kkt_residuals`).

Only numpy. Meant for small meshes (a few thousand dofs: the matrix is dense).

    python3 contact_reference.py case.nml     prints the contact summary of the solution
"""
import re
import sys

import numpy as np

MASK32 = 0xFFFFFFFF
GOLDEN = 0x9E3779B9


# ---------------------------------------------------------------------------- input
def parse_namelist(text):
    """{group: {variable: raw value}} of a simple namelist file (comments removed)."""
    text = re.sub(r"!.*", "", text)
    groups = {}
    for m in re.finditer(r"&(\w+)((?:'[^']*'|\"[^\"]*\"|[^'\"/])*)/", text, re.S):
        body = m.group(2)
        starts = [a.start() for a in re.finditer(r"\w+(\([^)]*\))?\s*=", body)]
        items = {}
        for i, s in enumerate(starts):
            piece = body[s:starts[i + 1] if i + 1 < len(starts) else len(body)].strip().rstrip(",")
            name, value = piece.split("=", 1)
            items[name.strip().lower()] = value.strip()
        groups[m.group(1).lower()] = items
    return groups


def _real(s):
    return float(s.strip().lower().replace("d", "e"))


def _reals(s):
    return [_real(v) for v in s.split(",") if v.strip()]


def _ints(s):
    return [int(v) for v in s.split(",") if v.strip()]


def _logical(s):
    return s.strip().lower().strip(".").startswith("t")


def _string(s):
    return s.strip().strip("'\"").strip().lower()


class Case:
    """The settings of docs/INPUT.md the discrete problem depends on, with their defaults."""

    def __init__(self, groups):
        g = lambda grp, var, default, conv: conv(groups[grp][var]) if var in groups.get(grp, {}) else default
        self.nsub = g("mesh", "nsub", [2, 2, 2], _ints)
        self.nel = g("mesh", "nel", [4, 4, 4], _ints)
        self.lengths = g("mesh", "lengths", [1.0, 1.0, 1.0], _reals)
        self.distortion = g("mesh", "distortion", 0.0, _real)
        self.seed = g("mesh", "distortion_seed", 1, lambda s: int(s))
        self.decomposition = g("mesh", "decomposition", "box", _string)
        self.young = g("material", "young", 2.1e5, _real)
        self.poisson = g("material", "poisson", 0.3, _real)
        self.variation = g("material", "variation", "none", _string)
        self.contrast = g("material", "contrast", 1.0, _real)
        self.top_pressure = g("load", "top_pressure", 0.0, _real)
        self.top_dirichlet = g("boundary", "top_dirichlet", True, _logical)
        self.top_displacement = g("boundary", "top_displacement", [0.0, 0.0, -0.005], _reals)
        self.symmetry_x0 = g("boundary", "symmetry_x0", False, _logical)
        self.symmetry_y0 = g("boundary", "symmetry_y0", False, _logical)
        self.shape = g("obstacle", "shape", "sphere", _string)
        self.radius = g("obstacle", "radius", 1.0, _real)
        self.gap = g("obstacle", "gap", 0.0, _real)
        self.axis = g("obstacle", "axis", [self.lengths[0] / 2, self.lengths[1] / 2], _reals)
        if self.variation not in ("none", "checkerboard"):
            raise ValueError("reference: material variation %r not supported" % self.variation)
        if self.variation == "checkerboard" and self.decomposition != "box":
            raise ValueError("reference: the checkerboard needs box subdomains")
        if not self.top_dirichlet and not (self.symmetry_x0 and self.symmetry_y0 and self.shape != "none"):
            raise ValueError("reference: needs top_dirichlet, or both symmetry planes and an obstacle")

    @staticmethod
    def read(path):
        with open(path) as f:
            return Case(parse_namelist(f.read()))


# ---------------------------------------------------------------------------- mesh
def _mix32(x):
    x ^= x >> 16
    x = (x * 0x7FEB352D) & MASK32
    x ^= x >> 15
    x = (x * 0x846CA68B) & MASK32
    x ^= x >> 16
    return x


def hash_unit(a, b, seed):
    """docs/CASES.md "Distortion": a number in [0, 1) from (node gid, component, seed), the
    'lowbias32' finalizer applied to the seed, then to (h xor a) + golden, then (h xor b) + golden."""
    h = _mix32(seed & MASK32)
    h = _mix32(((h ^ (a & MASK32)) + GOLDEN) & MASK32)
    h = _mix32(((h ^ (b & MASK32)) + GOLDEN) & MASK32)
    return h / 4294967296.0


class Mesh:
    def __init__(self, case):
        self.ng = np.array(case.nsub) * np.array(case.nel)
        self.h = np.array(case.lengths) / self.ng
        n1 = self.ng + 1
        k, j, i = np.meshgrid(np.arange(n1[2]), np.arange(n1[1]), np.arange(n1[0]), indexing="ij")
        self.ijk = np.column_stack([i.ravel(), j.ravel(), k.ravel()])        # node gid - 1 = i + n1x (j + n1y k)
        self.nn = len(self.ijk)
        x = self.ijk * self.h
        for c in range(3):
            x[self.ijk[:, c] == self.ng[c], c] = case.lengths[c]
        if case.distortion > 0:
            inner = np.all((self.ijk > 0) & (self.ijk < self.ng), axis=1)
            for n in np.nonzero(inner)[0]:
                for c in range(3):
                    x[n, c] += case.distortion * self.h[c] * (2 * hash_unit(int(n) + 1, c + 1, case.seed) - 1)
        self.x = x
        ek, ej, ei = np.meshgrid(np.arange(self.ng[2]), np.arange(self.ng[1]), np.arange(self.ng[0]), indexing="ij")
        eijk = np.column_stack([ei.ravel(), ej.ravel(), ek.ravel()])
        corner = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
        self.elements = np.column_stack([self.node_index(eijk + np.array(c)) for c in corner])
        self.element_ijk = eijk

    def node_index(self, ijk):
        n1 = self.ng + 1
        ijk = np.asarray(ijk)
        return ijk[..., 0] + n1[0] * (ijk[..., 1] + n1[1] * ijk[..., 2])


# ---------------------------------------------------------------------------- Q1 stiffness
_REF = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                 [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)
_G = 1 / np.sqrt(3.0)
_POINTS = np.array([[p, q, r] for r in (-_G, _G) for q in (-_G, _G) for p in (-_G, _G)])


def elasticity_matrix(young, nu):
    lam = young * nu / ((1 + nu) * (1 - 2 * nu))
    mu = young / (2 * (1 + nu))
    d = np.zeros((6, 6))
    d[:3, :3] = lam
    d[np.arange(3), np.arange(3)] = lam + 2 * mu
    d[np.arange(3, 6), np.arange(3, 6)] = mu
    return d


def element_stiffness(xe, young, nu):
    """Stiffness (ne, 24, 24) of the elements with corner coordinates xe (ne, 8, 3): the dense
    B^T D B det J summed over the 2x2x2 Gauss points (unit weights), engineering shear strains."""
    d = elasticity_matrix(young, nu)
    ne = xe.shape[0]
    ke = np.zeros((ne, 24, 24))
    for xi in _POINTS:
        f = 1 + _REF * xi                                              # (8, 3)
        dn = np.column_stack([_REF[:, 0] * f[:, 1] * f[:, 2], f[:, 0] * _REF[:, 1] * f[:, 2],
                              f[:, 0] * f[:, 1] * _REF[:, 2]]) / 8      # dN_a / dxi_j
        jac = np.einsum("eai,aj->eij", xe, dn)                         # dx_i / dxi_j
        det = np.linalg.det(jac)
        if not np.all(det > 0):
            raise ValueError("reference: element with a non-positive Jacobian")
        grad = np.einsum("aj,eji->eai", dn, np.linalg.inv(jac))        # dN_a / dx_i
        b = np.zeros((ne, 6, 24))
        for a in range(8):
            gx, gy, gz = grad[:, a, 0], grad[:, a, 1], grad[:, a, 2]
            c = 3 * a
            b[:, 0, c], b[:, 1, c + 1], b[:, 2, c + 2] = gx, gy, gz
            b[:, 3, c], b[:, 3, c + 1] = gy, gx
            b[:, 4, c + 1], b[:, 4, c + 2] = gz, gy
            b[:, 5, c], b[:, 5, c + 2] = gz, gx
        ke += np.einsum("eki,kl,elj,e->eij", b, d, b, det)
    return ke


def element_moduli(case, mesh):
    """Young's modulus per element: the checkerboard of box subdomains (I+J+K odd: contrast*E)."""
    e = np.full(len(mesh.elements), case.young)
    if case.variation == "checkerboard":
        sub = mesh.element_ijk // np.array(case.nel)
        e[sub.sum(axis=1) % 2 == 1] *= case.contrast
    return e


# ---------------------------------------------------------------------------- the problem
class Problem:
    def __init__(self, case):
        self.case = case
        m = self.mesh = Mesh(case)
        n = 3 * m.nn
        self.ndof = n
        xe = m.x[m.elements]
        moduli = element_moduli(case, m)
        self.k = np.zeros((n, n))
        dofs = (3 * m.elements[:, :, None] + np.arange(3)).reshape(len(m.elements), 24)
        for value in np.unique(moduli):
            sel = moduli == value
            ke = element_stiffness(xe[sel], value, case.poisson)
            for e, kk in zip(dofs[sel], ke):
                self.k[np.ix_(e, e)] += kk
        # top pressure: a dead load -p e_z, consistent nodal forces (the top face stays flat)
        self.f = np.zeros(n)
        if case.top_pressure != 0:
            top = m.elements[m.element_ijk[:, 2] == m.ng[2] - 1][:, 4:]
            for face in top:
                xf = m.x[face]
                area = np.linalg.norm(np.cross(xf[1] - xf[0], xf[3] - xf[0]))   # a rectangle
                for a in face:
                    self.f[3 * a + 2] -= case.top_pressure * area / 4
        # Dirichlet conditions (the top face decides on the top face)
        self.fixed = np.zeros(n, dtype=bool)
        self.value = np.zeros(n)
        ijk = m.ijk
        if case.symmetry_x0:
            self.fixed[3 * np.nonzero(ijk[:, 0] == 0)[0]] = True
        if case.symmetry_y0:
            self.fixed[3 * np.nonzero(ijk[:, 1] == 0)[0] + 1] = True
        top = np.nonzero(ijk[:, 2] == m.ng[2])[0]
        for c in range(3 if case.top_dirichlet else 0):
            self.fixed[3 * top + c] = True
            self.value[3 * top + c] = case.top_displacement[c]
        # contact rows: bottom nodes above the obstacle, -u_z <= g = z - psi
        bottom = np.nonzero(ijk[:, 2] == 0)[0]
        bottom = bottom[~self.fixed[3 * bottom + 2]]
        xb = m.x[bottom]
        if case.shape == "plane":
            psi = np.full(len(bottom), -case.gap)
        elif case.shape == "sphere":
            r2 = (xb[:, 0] - case.axis[0]) ** 2 + (xb[:, 1] - case.axis[1]) ** 2
            keep = r2 <= case.radius ** 2
            bottom, xb, r2 = bottom[keep], xb[keep], r2[keep]
            psi = -case.radius - case.gap + np.sqrt(case.radius ** 2 - r2)
        else:
            bottom, xb, psi = bottom[:0], xb[:0], np.zeros(0)
        self.contact_nodes = bottom
        self.contact_dofs = 3 * bottom + 2
        self.g = xb[:, 2] - psi
        # tributary areas of the contact nodes (the bottom face is flat: hx hy, halved per edge)
        w = np.full(len(bottom), m.h[0] * m.h[1])
        for c in range(2):
            on_edge = (m.ijk[bottom, c] == 0) | (m.ijk[bottom, c] == m.ng[c])
            w[on_edge] /= 2
        self.area = w

    def solve_with(self, active):
        """u with u_D = value, u_z = -g on the active contact rows, K u = f on the rest; the
        contact forces lambda = (K u - f) at the contact dofs (zero off the active set)."""
        fixed = self.fixed.copy()
        value = self.value.copy()
        fixed[self.contact_dofs[active]] = True
        value[self.contact_dofs[active]] = -self.g[active]
        free = ~fixed
        u = value.copy()
        rhs = self.f[free] - self.k[np.ix_(free, fixed)] @ value[fixed]
        u[free] = np.linalg.solve(self.k[np.ix_(free, free)], rhs)
        lam = np.zeros(len(self.contact_dofs))
        r = self.k[self.contact_dofs[active]] @ u - self.f[self.contact_dofs[active]]
        lam[active] = r
        return u, lam

    def solve(self, max_iterations=100):
        """Primal-dual active set iteration from the empty set (from the full set when the top
        face is free: then only the contact holds u_z, and K restricted to the free dofs is
        singular without it); returns (u (nn, 3), lambda)."""
        c = np.mean(np.diag(self.k))
        active = np.full(len(self.contact_dofs), not self.case.top_dirichlet)
        seen = set()
        for it in range(max_iterations):
            u, lam = self.solve_with(active)
            new = lam - c * (u[self.contact_dofs] + self.g) > 0
            key = new.tobytes()
            if np.array_equal(new, active):
                self.iterations = it + 1
                self.u, self.lam = u.reshape(-1, 3), lam
                return self.u, lam
            if key in seen:
                raise RuntimeError("reference: the active set iteration cycles")
            seen.add(active.tobytes())
            active = new
        raise RuntimeError("reference: no converged active set after %d iterations" % max_iterations)

    def kkt_residuals(self):
        """Relative KKT residuals of the reference solution (all near round-off when it is right)."""
        u = self.u.ravel()
        r = self.k @ u - self.f
        r[self.contact_dofs] -= self.lam
        scale_f = np.abs(self.k).dot(np.abs(u)).max() + np.abs(self.f).max()
        uz = u[self.contact_dofs]
        scale_u = np.abs(u).max()
        scale_l = max(np.abs(self.lam).max(), 1e-300)
        return {
            "equilibrium": np.abs(r[~self.fixed]).max() / scale_f,
            "dirichlet": np.abs(u[self.fixed] - self.value[self.fixed]).max() / scale_u,
            "penetration": max(0.0, (-(uz + self.g)).max(initial=0.0)) / scale_u,
            "dual_feasibility": max(0.0, (-self.lam).max(initial=0.0)) / scale_l,
            "complementarity": np.abs(self.lam * (uz + self.g)).max(initial=0.0) / (scale_l * scale_u),
        }

    def pressure(self):
        return self.lam / self.area


def element_young(case, subdomain):
    """Young's modulus of elements of the subdomains `subdomain` (ids from 1, box numbering
    1 + I + Nx (J + Ny K)): the checkerboard of docs/CASES.md."""
    e = np.full(len(subdomain), case.young)
    if case.variation == "checkerboard":
        r = np.asarray(subdomain) - 1
        i, r = r % case.nsub[0], r // case.nsub[0]
        j, k = r % case.nsub[1], r // case.nsub[1]
        e[(i + j + k) % 2 == 1] *= case.contrast
    return e


def copy_reactions(case, x, u, connectivity, subdomain):
    """K_s u_s per node copy, assembled element by element over the subdomain copies of a
    decomposed field (the HDF5 output: one row per copy, connectivity into the rows): the
    internal forces of each subdomain. Summed over the copies of a node the gluing forces
    cancel, so their sum over the face z = 0 is the total force the obstacle exerts."""
    conn = np.asarray(connectivity)
    young = element_young(case, subdomain)
    r = np.zeros_like(u)
    for value in np.unique(young):
        sel = young == value
        ke = element_stiffness(x[conn[sel]], value, case.poisson)
        fe = np.einsum("eij,ej->ei", ke, u[conn[sel]].reshape(-1, 24)).reshape(-1, 8, 3)
        np.add.at(r, conn[sel], fe)
    return r


def main():
    p = Problem(Case.read(sys.argv[1]))
    u, lam = p.solve()
    print("dofs %d, contact rows %d, active %d, PDAS iterations %d" % (p.ndof, len(lam), int((lam > 0).sum()),
                                                                     p.iterations))
    print("total force %.10e, max |u| %.6e" % (lam.sum(), np.abs(u).max()))
    for k, v in p.kkt_residuals().items():
        print("  %-16s %.3e" % (k, v))


if __name__ == "__main__":
    main()
