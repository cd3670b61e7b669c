// The silicone beam's closed STL surface (beam.stl, in mm) as a tetrahedral volume
// mesh kelvin reads:   gmsh -3 beam.geo -o beam.msh
// ClassifySurfaces splits the triangulated surface into its faces at 40° creases and
// CreateGeometry makes them surfaces Gmsh can remesh at the size below; the volume
// inside them is then filled with tetrahedra.
Merge "beam.stl";
ClassifySurfaces{40 * Pi / 180, 1, 1, Pi};
CreateGeometry;
Surface Loop(1) = Surface{:};
Volume(1) = {1};
Physical Volume("beam") = {1};
Mesh.MeshSizeMax = 5;        // target element size, in the STL's units (mm)
Mesh.ScalingFactor = 0.001;  // mm → m, kelvin's unit
