// examples/spatial-slidercrank/rod.geo: the flexible connecting rod of the spatial slider-crank
// (examples/spatial-slidercrank/README.md): a solid steel cylinder along x, L = 0.3 m (the
// IFToMM benchmark's rod length), radius R = 0.01 m (our choice, documented in the README).
// OpenCASCADE kernel. Physical groups: end0 (face x = 0, the crank pin's spherical joint),
// end1 (face x = L, the slider's universal joint), body (the volume).
//   mesh2fe rod.geo --size 0.004 --interface end0@0,0,0 --interface end1@0.3,0,0
SetFactory("OpenCASCADE");
L = 0.3;
R = 0.01;
Cylinder(1) = {0, 0, 0, L, 0, 0, R};
// the end faces, found by position (robust to the kernel's face numbering)
e = 1e-6;
s0() = Surface In BoundingBox{-e, -R - e, -R - e, e, R + e, R + e};
s1() = Surface In BoundingBox{L - e, -R - e, -R - e, L + e, R + e, R + e};
Physical Surface("end0") = {s0()};
Physical Surface("end1") = {s1()};
Physical Volume("body") = {1};
// default element size when mesh2fe gets no --size: half the radius
Mesh.MeshSizeMax = R / 2;
