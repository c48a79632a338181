#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Independent reader for voxlight's mesh exports (tests/iso/test_export.cpp).

usage: read_mesh.py FILE.(ply|obj|glb)
Prints one JSON object: vertex and face counts as VTK's reader (vtkPLYReader, vtkOBJReader,
vtkGLTFReader) sees them, the distinct vertex colours as the file stores them (VTK's RGB array for
PLY, the `v x y z r g b` fields for OBJ, COLOR_0 for glTF, read with the standard library), and for
glTF the node matrix and asset extras. Exit code 77 when Debian's python3-vtk9 is missing.
"""
import json
import struct
import sys

try:
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonDataModel import vtkCompositeDataSet, vtkPolyData
    from vtkmodules.vtkIOGeometry import vtkGLTFReader, vtkOBJReader
    from vtkmodules.vtkIOPLY import vtkPLYReader
except ImportError as e:
    print(f"python3-vtk9 missing: {e}", file=sys.stderr)
    sys.exit(77)


def leaves(data):
    if isinstance(data, vtkPolyData):
        yield data
        return
    it = data.NewIterator()
    it.InitTraversal()
    while not it.IsDoneWithTraversal():
        yield it.GetCurrentDataObject()
        it.GoToNextItem()


PLY_TYPES = {"float": "f", "float32": "f", "uchar": "B", "uint8": "B", "int": "i", "int32": "i"}


def ply_vertex_records(path):
    """The vertex element of a binary little-endian PLY by hand (the PLY spec): property names
    and one tuple per vertex — what VTK's reader does not expose (extra properties)."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    names, fmt, count, element = [], "<", 0, None
    for line in data[:end].decode("ascii").splitlines():
        w = line.split()
        if w[:1] == ["format"]:
            assert w[1] == "binary_little_endian", w
        elif w[:1] == ["element"]:
            element = w[1]
            if element == "vertex":
                count = int(w[2])
        elif w[:1] == ["property"] and element == "vertex":
            fmt += PLY_TYPES[w[1]]
            names.append(w[2])
    size = struct.calcsize(fmt)
    return names, [struct.unpack_from(fmt, data, end + i * size) for i in range(count)]


def read_ply(path):
    r = vtkPLYReader()
    r.SetFileName(path)
    r.Update()
    pd = r.GetOutput()
    rgb = vtk_to_numpy(pd.GetPointData().GetArray("RGB"))
    colours = sorted({tuple(int(c) for c in row) for row in rgb})
    out = {"vertices": pd.GetNumberOfPoints(), "faces": pd.GetNumberOfCells(),
           "has_normals": pd.GetPointData().GetNormals() is not None, "colours": colours}
    names, records = ply_vertex_records(path)
    sh = [i for i, n in enumerate(names) if n.startswith("sh")]
    if sh:  # per vertex: nx ny nz, red green blue, then the SH transfer properties in order
        keep = [names.index(n) for n in ("nx", "ny", "nz", "red", "green", "blue")] + sh
        out["sh_names"] = [names[i] for i in sh]
        out["sh_vertices"] = [[rec[i] for i in keep] for rec in records]
    return out


def read_obj(path):
    r = vtkOBJReader()
    r.SetFileName(path)
    r.Update()
    pd = r.GetOutput()
    colours = set()
    comments = []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                colours.add(tuple(round(float(x), 4) for x in line.split()[4:7]))
            elif line.startswith("#"):
                comments.append(line[1:].strip())
    return {"vertices": pd.GetNumberOfPoints(), "faces": pd.GetNumberOfCells(),
            "has_normals": pd.GetPointData().GetNormals() is not None,
            "colours": sorted(colours), "comments": comments}


def read_glb(path):
    r = vtkGLTFReader()
    r.SetFileName(path)
    r.Update()
    nv = nf = 0
    for pd in leaves(r.GetOutput()):
        nv += pd.GetNumberOfPoints()
        nf += pd.GetNumberOfCells()
    # The container by hand (glTF 2.0 §4.4): header, JSON chunk, BIN chunk.
    with open(path, "rb") as f:
        data = f.read()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and length == len(data)
    jlen, jtype = struct.unpack_from("<II", data, 12)
    doc = json.loads(data[20:20 + jlen])
    blen, _ = struct.unpack_from("<II", data, 20 + jlen)
    binary = data[28 + jlen:28 + jlen + blen]
    prim = doc["meshes"][0]["primitives"][0]
    acc = doc["accessors"][prim["attributes"]["COLOR_0"]]
    view = doc["bufferViews"][acc["bufferView"]]
    off = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    values = struct.unpack_from(f"<{3 * acc['count']}f", binary, off)
    colours = sorted({tuple(round(v, 5) for v in values[i:i + 3]) for i in range(0, len(values), 3)})
    return {"vertices": nv, "faces": nf, "colours": colours,
            "attributes": sorted(prim["attributes"].keys()),
            "matrix": doc["nodes"][0].get("matrix"), "extras": doc["asset"].get("extras", {})}


def main():
    path = sys.argv[1]
    ext = path.lower().rsplit(".", 1)[-1]
    out = {"ply": read_ply, "obj": read_obj, "glb": read_glb}[ext](path)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
