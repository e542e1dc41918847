// examples/sarrus/link.geo: one link of the Sarrus mechanism (proximal or distal), a line of
// 2-node beam elements, L = 0.15 m along x (the body frame); the element size, section and
// material come from the command line (examples/sarrus/sarrus.py):
//   mesh2fe link.geo --size 0.015 --circle 0.004 --E 210e9 --nu 0.3 --rho 7850 \
//           --interface end0 --interface end1
// Physical groups: end0 (x = 0, the joint towards the ground), end1 (x = L).
L = 0.15;
Point(1) = {0, 0, 0};
Point(2) = {L, 0, 0};
Line(1) = {1, 2};
Physical Point("end0") = {1};
Physical Point("end1") = {2};
Physical Curve("body") = {1};
Mesh.MeshSizeMax = L / 10;
