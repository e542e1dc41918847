// examples/batch/bracket.geo: the angle bracket of the batch example (a family of bodies).
// SPDX-License-Identifier: MIT
//
// An L-shaped steel bracket: a base plate L x W (x, y) of wall thickness T, with a bolt hole
// of radius R at x = R + T... and an upright wall of height H at x = L (the wall thickness T
// as well). Physical groups: hole (the bore, where a bolt holds it), top (the upper face of
// the upright, where a joint acts), body (the volume).
//
// The parameters L, W, H, T, R are defined before this text: the batch Makefile writes each
// body's BODY.geo as its parameter lines followed by this file (mesh2fe has no option that
// sets .geo numbers; see examples/batch/README.md). Used alone, the defaults below apply.
If (!Exists(L))
  L = 0.08;
EndIf
If (!Exists(W))
  W = 0.03;
EndIf
If (!Exists(H))
  H = 0.05;
EndIf
If (!Exists(T))
  T = 0.004;
EndIf
If (!Exists(R))
  R = 0.005;
EndIf
If (!Exists(h))
  h = 0.006;
EndIf
SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, L, W, T};
Box(2) = {L - T, 0, 0, T, W, H};
xh = 2 * R + T;
Cylinder(3) = {xh, W / 2, -T, 0, 0, 3 * T, R};
BooleanUnion(4) = {Volume{1}; Delete;}{Volume{2}; Delete;};
BooleanDifference(5) = {Volume{4}; Delete;}{Volume{3}; Delete;};
e = 1e-6;
bore() = Surface In BoundingBox{xh - R - e, W / 2 - R - e, -e, xh + R + e, W / 2 + R + e, T + e};
top() = Surface In BoundingBox{L - T - e, -e, H - e, L + e, W + e, H + e};
Physical Surface("hole") = {bore()};
Physical Surface("top") = {top()};
Physical Volume("body") = {5};
Mesh.MeshSizeMax = h;
Mesh.SecondOrderLinear = 1;  // straight tet10 edges: coarse curved ones on the bore can invert
