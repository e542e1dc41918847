// examples/nlink/link.geo: one link of the N-link pendulum, a line of 2-node beam elements
// L = 0.5 m along x (the body frame), 10 elements; the section and material come from the
// command line (examples/nlink/nlink.py):
//   mesh2fe link.geo --circle 0.01 --E 210e9 --nu 0.3 --rho 7850 \
//           --interface end0 --interface end1
// Physical groups: end0 (x = 0, the joint to the previous link), end1 (x = L).
L = 0.5;
Point(1) = {0, 0, 0};
Point(2) = {L, 0, 0};
Line(1) = {1, 2};
Physical Point("end0") = {1};
Physical Point("end1") = {2};
Physical Curve("body") = {1};
Mesh.MeshSizeMax = L / 10;
