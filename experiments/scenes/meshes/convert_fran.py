"""Convert the VTK example face scan ``fran_cut.vtk`` into ``fran_cut.ply`` (run once).

The legacy VTK polydata file is read and written with VTK itself (``pip install vtk``,
not a dependency of invsss: the converted PLY is what the repository ships and what
``experiments/make_synthetic.py`` loads with trimesh). The conversion keeps the points
(in metres, as stored), the triangles and the texture coordinates; nothing else in the
file is used::

    python experiments/scenes/meshes/convert_fran.py PATH/TO/fran_cut.vtk experiments/scenes/meshes/fran_cut.ply
"""

import sys

import vtk


def convert(vtk_path: str, ply_path: str) -> None:
    reader = vtk.vtkPolyDataReader()
    reader.SetFileName(vtk_path)
    reader.Update()
    mesh = reader.GetOutput()
    if mesh.GetNumberOfPolys() == 0 or mesh.GetPointData().GetTCoords() is None:
        raise SystemExit(f"{vtk_path}: expected polygons with texture coordinates")
    triangles = vtk.vtkTriangleFilter()  # the scan is triangles already; this makes sure
    triangles.SetInputData(mesh)
    writer = vtk.vtkPLYWriter()
    writer.SetInputConnection(triangles.GetOutputPort())
    writer.SetFileName(ply_path)
    writer.SetFileTypeToBinary()
    writer.SetTextureCoordinatesNameToUV()
    if not writer.Write():
        raise SystemExit(f"{ply_path}: cannot write")


if __name__ == "__main__":
    convert(*sys.argv[1:3])
