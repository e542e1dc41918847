// examples/slidercrank/crank.geo: the rigid crank of the planar slider-crank (README.md; our
// dimensions, the paper gives only a figure): an aluminium bar 0.14 x 0.04 x 0.02 m, its axis
// along y, the pivot at y = 0 and the crank pin at y = 0.1 (0.02 m of material beyond each).
// The scene gives fmbd-run the same bar as a `box` (mass 0.30352 kg at rho 2710); this file
// lets mesh2fe check that mass (mesh2fe crank.geo --rho 2710 prints it) and draws the part.
SetFactory("OpenCASCADE");
Box(1) = {-0.02, -0.02, -0.01, 0.04, 0.14, 0.02};
Physical Volume("body") = {1};
Mesh.MeshSizeMax = 0.01;
