// examples/geometry/rod.geo: the papers' steel rod, a solid cylinder along x
// L = 0.3 m, radius R = 0.015 m (L/D = 10). OpenCASCADE kernel.
// Physical groups: end0 (face x = 0), end1 (face x = L), body (the volume).
//   mesh2fe rod.geo --size 0.005 --interface end0 --interface end1
SetFactory("OpenCASCADE");
L = 0.3;
R = 0.015;
Cylinder(1) = {0, 0, 0, L, 0, 0, R};
// the faces at the ends, found by position (robust to the kernel's face numbering)
e = 1e-6;
s0() = Surface In BoundingBox{-e, -R - e, -R - e, e, R + e, R + e};
s1() = Surface In BoundingBox{L - e, -R - e, -R - e, L + e, R + e, R + e};
Physical Surface("end0") = {s0()};
Physical Surface("end1") = {s1()};
Physical Volume("body") = {1};
// default element size when mesh2fe gets no --size: a quarter of the radius
Mesh.MeshSizeMax = R / 2;
