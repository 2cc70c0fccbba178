"""Re-save a .vtp with VTK itself in every encoding its writers produce.

Usage: vtk_variants.py IN.vtp OUT_DIR

VTK (the PyPI wheel, the library 3D Slicer and ParaView save models with) reads IN.vtp, adds a
`SPACE` = "RAS" field-data string (how Slicer marks a model's frame) and writes OUT_DIR/NAME.vtp
for every XML data mode (ascii, binary, appended raw, appended base64), compressor (none, zlib),
header type (UInt32, UInt64) and byte order, plus Float32 points and legacy .vtk (ASCII and
binary). It prints one line per file written, and the points and cells VTK read from IN.vtp.
"""

import sys
from pathlib import Path

from vtkmodules.vtkCommonCore import vtkFloatArray, vtkPoints, vtkStringArray
from vtkmodules.vtkCommonDataModel import vtkPolyData
from vtkmodules.vtkIOLegacy import vtkPolyDataWriter
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader, vtkXMLPolyDataWriter


def main() -> None:
    src, out = Path(sys.argv[1]), Path(sys.argv[2])
    out.mkdir(parents=True, exist_ok=True)
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(src))
    reader.Update()
    mesh = reader.GetOutput()
    print(f"read {mesh.GetNumberOfPoints()} points {mesh.GetNumberOfPolys()} polys")
    # Marked as the active vectors, as Slicer and ParaView do: <PointData Vectors="...">.
    mesh.GetPointData().SetActiveVectors("displacement_mm")
    space = vtkStringArray()
    space.SetName("SPACE")
    space.InsertNextValue("RAS")
    mesh.GetFieldData().AddArray(space)

    for mode in ("ascii", "binary", "appended-raw", "appended-base64"):
        for compressor in ("none", "zlib"):
            for header in ("UInt32", "UInt64"):
                if mode == "ascii" and (compressor, header) != ("none", "UInt32"):
                    continue
                w = vtkXMLPolyDataWriter()
                w.SetInputData(mesh)
                if mode == "ascii":
                    w.SetDataModeToAscii()
                elif mode == "binary":
                    w.SetDataModeToBinary()
                else:
                    w.SetDataModeToAppended()
                    w.SetEncodeAppendedData(mode == "appended-base64")
                if compressor == "none":
                    w.SetCompressorTypeToNone()
                else:
                    w.SetCompressorTypeToZLib()
                    # Small blocks, so that arrays span several.
                    w.SetBlockSize(4096)
                if header == "UInt32":
                    w.SetHeaderTypeToUInt32()
                else:
                    w.SetHeaderTypeToUInt64()
                write(w, out / f"{mode}-{compressor}-{header}.vtp")

    w = vtkXMLPolyDataWriter()
    w.SetInputData(mesh)
    w.SetByteOrderToBigEndian()
    w.SetCompressorTypeToNone()
    write(w, out / "appended-raw-bigendian.vtp")

    single = vtkPolyData()
    single.DeepCopy(mesh)
    pts = vtkPoints()
    pts.SetDataTypeToFloat()
    pts.DeepCopy(mesh.GetPoints())
    floats = vtkFloatArray()
    floats.DeepCopy(mesh.GetPoints().GetData())
    pts.SetData(floats)
    single.SetPoints(pts)
    w = vtkXMLPolyDataWriter()
    w.SetInputData(single)
    write(w, out / "float32-points-default.vtp")

    for kind in ("ascii", "binary"):
        w = vtkPolyDataWriter()
        w.SetInputData(mesh)
        if kind == "ascii":
            w.SetFileTypeToASCII()
        else:
            w.SetFileTypeToBinary()
        w.SetHeader("written by VTK. SPACE=RAS")
        write(w, out / f"legacy-{kind}.vtk")


def write(w, path: Path) -> None:
    w.SetFileName(str(path))
    if w.Write() != 1:
        raise SystemExit(f"VTK could not write {path}")
    print(f"wrote {path.name}")


if __name__ == "__main__":
    main()
