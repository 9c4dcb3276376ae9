#!/usr/bin/python3
"""Time METIS_PartGraphKway alone (through ctypes, Debian's libmetis.so.5) on
the face graph of an n x n x n grid of blocks into p parts, with METIS's
default options: what `&mesh decomposition = 'metis'` costs rank 0 before
anything else can start (inputs/hard/metis.nml: n = 16, p = 64).

    /usr/bin/python3 tools/metis_partition_time.py [n] [p] [repetitions]

Prints the return code, the edge cut and the time of each repetition.
"""
import ctypes
import sys
import time


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 16
    parts = int(sys.argv[2]) if len(sys.argv) > 2 else 64
    reps = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    lib = ctypes.CDLL("libmetis.so.5")
    xadj, adj = [0], []
    for k in range(n):
        for j in range(n):
            for i in range(n):
                # face neighbours in ascending id order, as src/mesh/decomposition.f90 gives them
                for d in [(0, 0, -1), (0, -1, 0), (-1, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)]:
                    a, b, c = i + d[0], j + d[1], k + d[2]
                    if 0 <= a < n and 0 <= b < n and 0 <= c < n:
                        adj.append(a + n * (b + n * c))
                xadj.append(len(adj))
    idx = ctypes.c_int32
    c_xadj = (idx * len(xadj))(*xadj)
    c_adj = (idx * len(adj))(*adj)
    nv, ncon, np_, cut = idx(n ** 3), idx(1), idx(parts), idx(0)
    part = (idx * n ** 3)()
    options = (idx * 40)()
    lib.METIS_SetDefaultOptions(options)
    for _ in range(reps):
        t = time.perf_counter()
        rc = lib.METIS_PartGraphKway(ctypes.byref(nv), ctypes.byref(ncon), c_xadj, c_adj, None, None, None,
                                     ctypes.byref(np_), None, None, options, ctypes.byref(cut), part)
        print("rc %d, edge cut %d, %.1f ms" % (rc, cut.value, (time.perf_counter() - t) * 1e3))


if __name__ == "__main__":
    main()
