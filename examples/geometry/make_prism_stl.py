#!/usr/bin/python3
"""examples/geometry/make_prism_stl.py: write rod_faceted.stl, the rod of rod.geo as a closed
faceted surface (a regular N-gon prism along x), for the CGAL path of mesh2fe.

    /usr/bin/python3 make_prism_stl.py [N] > rod_faceted.stl

L = 0.3 m, circumradius R = 0.015 m, N = 24 sides by default. Its exact volume is
L * N/2 * R^2 * sin(2 pi / N) (= 2.0964e-4 m^3 for N = 24, 1.1 % below the round cylinder).
Triangles are oriented outward (right-hand rule), as STL asks."""
import math
import sys

L, R = 0.3, 0.015
N = int(sys.argv[1]) if len(sys.argv) > 1 else 24
ring = [(R * math.cos(2 * math.pi * k / N), R * math.sin(2 * math.pi * k / N)) for k in range(N)]


def facet(a, b, c):
    u = [b[i] - a[i] for i in range(3)]
    v = [c[i] - a[i] for i in range(3)]
    n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
    s = math.sqrt(sum(x * x for x in n))
    out = ["  facet normal %.9e %.9e %.9e" % tuple(x / s for x in n), "    outer loop"]
    out += ["      vertex %.9e %.9e %.9e" % p for p in (a, b, c)]
    out += ["    endloop", "  endfacet"]
    return "\n".join(out)


lines = ["solid rod_faceted"]
c0, c1 = (0.0, 0.0, 0.0), (L, 0.0, 0.0)
for k in range(N):
    y0, z0 = ring[k]
    y1, z1 = ring[(k + 1) % N]
    p0, p1 = (0.0, y0, z0), (0.0, y1, z1)
    q0, q1 = (L, y0, z0), (L, y1, z1)
    lines.append(facet(c0, p1, p0))   # end x = 0, normal -x
    lines.append(facet(c1, q0, q1))   # end x = L, normal +x
    lines.append(facet(p0, p1, q1))   # side
    lines.append(facet(p0, q1, q0))
lines.append("endsolid rod_faceted")
print("\n".join(lines))
