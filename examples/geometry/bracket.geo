// examples/geometry/bracket.geo: a steel plate with a bolt hole, two interface faces
// Plate 0.10 x 0.04 x 0.005 m (x, y, z), a hole of radius 0.008 m through it at (0.025, 0.02).
// Physical groups: hole (the bore, where a bolt holds it), tip (the face x = 0.10, where a
// load or a joint acts), body (the volume).
//   mesh2fe bracket.geo --size 0.004 --interface hole:rbe2 --interface tip:rbe3
SetFactory("OpenCASCADE");
Lx = 0.10; Ly = 0.04; T = 0.005; Rh = 0.008; xh = 0.025;
Box(1) = {0, 0, 0, Lx, Ly, T};
Cylinder(2) = {xh, Ly / 2, -T, 0, 0, 3 * T, Rh};
BooleanDifference(3) = {Volume{1}; Delete;}{Volume{2}; Delete;};
e = 1e-6;
bore() = Surface In BoundingBox{xh - Rh - e, Ly / 2 - Rh - e, -e, xh + Rh + e, Ly / 2 + Rh + e, T + e};
tip() = Surface In BoundingBox{Lx - e, -e, -e, Lx + e, Ly + e, T + e};
Physical Surface("hole") = {bore()};
Physical Surface("tip") = {tip()};
Physical Volume("body") = {3};
Mesh.MeshSizeMax = 0.005;
