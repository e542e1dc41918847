// examples/geometry/rodbeam.geo: the rod of rod.geo as a line of 2-node beam elements
// L = 0.3 m along x; give the section on the command line (a solid circle of R = 0.015 m):
//   mesh2fe rodbeam.geo --circle 0.015 --interface end0 --interface end1
// Physical groups: end0 (point x = 0), end1 (point x = L), body (the curve).
L = 0.3;
Point(1) = {0, 0, 0};
Point(2) = {L, 0, 0};
Line(1) = {1, 2};
Physical Point("end0") = {1};
Physical Point("end1") = {2};
Physical Curve("body") = {1};
// default: 20 elements (mesh2fe --size H overrides)
Mesh.MeshSizeMax = L / 20;
