// examples/slidercrank/rod.geo: the flexible connecting rod of the planar slider-crank
// (examples/slidercrank/README.md; Han et al. 2020, section 5.2, whose figure gives the shape
// but not the dimensions: these are ours). Aluminium 6061-T6 in the scene's mesh2fe options.
// A flat bar with round ends (a stadium), bore centres 0.3 m apart on the x axis, width
// 2 Rb = 0.04 m, thickness T = 0.02 m (z from -T/2 to T/2), two bores of radius Rp = 0.01 m.
// OpenCASCADE kernel. Physical groups: bore0 (the inner surface of the bore at the origin,
// the crank pin), bore1 (the bore at x = 0.3, the slider's pin), body (the volume).
//   mesh2fe rod.geo --size 0.006 --interface bore0@0,0,0 --interface bore1@0.3,0,0
SetFactory("OpenCASCADE");
Lc = 0.3;    // bore centre distance
Rb = 0.02;   // half width = radius of the round ends
Rp = 0.01;   // bore radius
T = 0.02;    // thickness
Box(1) = {0, -Rb, -T / 2, Lc, 2 * Rb, T};
Cylinder(2) = {0, 0, -T / 2, 0, 0, T, Rb};
Cylinder(3) = {Lc, 0, -T / 2, 0, 0, T, Rb};
Cylinder(4) = {0, 0, -T, 0, 0, 2 * T, Rp};
Cylinder(5) = {Lc, 0, -T, 0, 0, 2 * T, Rp};
bar() = BooleanUnion{ Volume{1}; Delete; }{ Volume{2, 3}; Delete; };
rod() = BooleanDifference{ Volume{bar()}; Delete; }{ Volume{4, 5}; Delete; };
// the bores' inner surfaces, found by position (robust to the kernel's face numbering)
e = 1e-6;
b0() = Surface In BoundingBox{-Rp - e, -Rp - e, -T / 2 - e, Rp + e, Rp + e, T / 2 + e};
b1() = Surface In BoundingBox{Lc - Rp - e, -Rp - e, -T / 2 - e, Lc + Rp + e, Rp + e, T / 2 + e};
Physical Surface("bore0") = {b0()};
Physical Surface("bore1") = {b1()};
Physical Volume("body") = {rod()};
// default element size when mesh2fe gets no --size: half the bore radius
Mesh.MeshSizeMax = Rp / 2;
