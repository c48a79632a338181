#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Seed corpora for the fuzz targets (fuzz/), made fresh instead of kept in git.

    tools/make_fuzz_corpus.py OUTDIR [--voxlight build/voxlight]

Writes OUTDIR/<target>/ with a few small valid inputs per target (under ~4 KB each, so libFuzzer's
default max_len stays small and executions fast): voxlight's own phantom writer for NIfTI-1 (.nii,
.nii.gz), MetaImage (.mha) and VTI; nibabel (Debian's python3-nibabel) for NIfTI-2; VTK's Python
writer (python3-vtk9) for VTI variants (inline ascii/base64, appended raw, uncompressed); this
script for NRRD (attached, detached, gzip, space directions), MetaImage .mhd+raw, raw layouts, DICOM
(explicit and implicit VR little endian, written byte by byte) and GDCM's gdcmconv for the
compressed DICOM transfer syntaxes (JPEG 2000, JPEG-LS, RLE, JPEG lossless); example scenes for the
scene parser. Multi-file targets get their files joined by the separator VXLFUZZSPLIT
(fuzz/fuzz_common.h). Run by tools/fuzz.sh and .ci/run; needs Debian's /usr/bin/python3 for nibabel
and vtk.
"""
import argparse
import gzip
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import zlib

SPLIT = b"VXLFUZZSPLIT"
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def put(outdir, target, name, data):
    d = os.path.join(outdir, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def ramp(n, mod=251):
    return bytes((i * 7) % mod for i in range(n))


def int16le(values):
    return b"".join(struct.pack("<h", v) for v in values)


# --- NRRD and MetaImage text formats ------------------------------------------------------------
def nrrd_seeds(out):
    data8 = ramp(10 * 4 * 3)
    put(out, "nrrd", "uint8_raw.nrrd",
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 10 4 3\nencoding: raw\nspacings: 1 1 2\n\n" + data8)
    data16 = int16le([(i * 37) % 2000 - 1000 for i in range(12 * 3 * 2)])
    put(out, "nrrd", "int16_space.nrrd",
        b"NRRD0005\n# voxlight fuzz seed\ntype: short\ndimension: 3\nspace: left-posterior-superior\n"
        b"sizes: 12 3 2\nspace directions: (0.5,0,0) (0,-0.5,0) (0,0,2)\nkinds: domain domain domain\n"
        b"endian: little\nencoding: raw\nspace origin: (-3,4,5.5)\n\n" + data16)
    put(out, "nrrd", "float_gzip.nrrd",
        b"NRRD0004\ntype: float\ndimension: 3\nsizes: 10 2 2\nendian: little\nencoding: gzip\n"
        b"space: RAS\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nspace origin: (0,0,0)\n\n" +
        gzip.compress(struct.pack("<40f", *[i * 0.25 for i in range(40)]), mtime=0))
    put(out, "nrrd", "uint16_be.nrrd",
        b"NRRD0004\ntype: unsigned short\ndimension: 2\nsizes: 12 3\nendian: big\nencoding: raw\n"
        b"spacings: 0.7 0.7\n\n" + b"".join(struct.pack(">H", i * 100) for i in range(36)))
    # Detached: in.nhdr + in.raw (+ in.raw.gz), joined by the separator.
    put(out, "nrrd_detached", "raw.seed",
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 10 4 3\nencoding: raw\ndata file: in.raw\n" +
        SPLIT + data8)
    put(out, "nrrd_detached", "gzip_lps.seed",
        b"NRRD0005\ntype: int16\ndimension: 3\nspace: LPS\nsizes: 12 3 2\n"
        b"space directions: (0,1,0) (1,0,0) (0,0,-1.5)\nendian: little\nencoding: gzip\n"
        b"space origin: (1,2,3)\ndata file: in.raw.gz\n" + SPLIT + SPLIT +
        gzip.compress(data16, mtime=0))
    put(out, "nrrd_detached", "ascii.seed",
        b"NRRD0004\ntype: int\ndimension: 3\nsizes: 10 1 2\nencoding: ascii\ndata file: in.raw\n" +
        SPLIT + b" ".join(str(i * 3 - 9).encode() for i in range(20)) + b"\n")
    put(out, "nrrd_detached", "list.seed",
        b"NRRD0004\ntype: uint8\ndimension: 3\nsizes: 10 4 2\nencoding: raw\ndata file: LIST\n"
        b"in.raw\nin.raw.gz\n" + SPLIT + ramp(40) + SPLIT + ramp(40, 17))


def meta_seeds(out):
    head = (b"ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
            b"CompressedData = False\nTransformMatrix = 1 0 0 0 1 0 0 0 1\nOffset = -2 3 4.5\n"
            b"ElementSpacing = 0.5 0.5 2\nDimSize = 10 4 3\nAnatomicalOrientation = RAI\n")
    data16 = int16le([(i * 53) % 3000 - 1024 for i in range(120)])
    put(out, "metaimage_mhd", "short.seed",
        head + b"ElementType = MET_SHORT\nElementDataFile = in.raw\n" + SPLIT + data16)
    z = zlib.compress(ramp(120))
    put(out, "metaimage_mhd", "zlib.seed",
        head.replace(b"CompressedData = False", b"CompressedData = True\nCompressedDataSize = " +
                     str(len(z)).encode()) +
        b"ElementType = MET_UCHAR\nElementDataFile = in.zraw\n" + SPLIT + SPLIT + z)
    put(out, "metaimage_mhd", "pattern.seed",
        head.replace(b"DimSize = 10 4 3", b"DimSize = 10 4 2") +
        b"ElementType = MET_UCHAR\nElementDataFile = in.%s 1 2 1\n".replace(b"%s", b"%d") +
        SPLIT + ramp(40) + SPLIT + ramp(40, 13))
    put(out, "metaimage", "short_local.mha",
        head + b"ElementType = MET_SHORT\nElementDataFile = LOCAL\n" + data16)
    put(out, "metaimage", "float_local.mha",
        b"ObjectType = Image\nNDims = 2\nDimSize = 10 3\nElementType = MET_FLOAT\n"
        b"ElementSpacing = 1 1\nElementByteOrderMSB = False\nElementDataFile = LOCAL\n" +
        struct.pack("<30f", *[i * 0.5 for i in range(30)]))


def raw_seeds(out):
    def layout(dims, type_index, big, header, spacing):
        return (struct.pack("<3i", *dims) + bytes([type_index, 1 if big else 0]) +
                struct.pack("<H", header) + struct.pack("<3d", *spacing))
    put(out, "raw", "uint8.seed", layout((10, 4, 3), 0, False, 0, (1, 1, 1)) + ramp(120))
    put(out, "raw", "int16_header.seed",
        layout((10, 4, 2), 1, True, 16, (0.5, 0.5, 2)) + bytes(16) + ramp(160))
    put(out, "raw", "float.seed",
        layout((4, 4, 4), 3, False, 0, (1, 2, 3)) + struct.pack("<64f", *range(64)))


# --- DICOM, written byte by byte ------------------------------------------------------------------
EXPLICIT_LE = "1.2.840.10008.1.2.1"
IMPLICIT_LE = "1.2.840.10008.1.2"
CT_STORAGE = "1.2.840.10008.5.1.4.1.1.2"


def element(group, elem, vr, value, explicit=True):
    if isinstance(value, str):
        value = value.encode()
        if len(value) % 2:
            value += b"\0" if vr == "UI" else b" "
    if not explicit:
        return struct.pack("<HHI", group, elem, len(value)) + value
    if vr in ("OB", "OW", "SQ", "UN", "UT", "OF"):
        return struct.pack("<HH2sHI", group, elem, vr.encode(), 0, len(value)) + value
    return struct.pack("<HH2sH", group, elem, vr.encode(), len(value)) + value


def dicom_slice(rows, cols, z, instance, syntax=EXPLICIT_LE, series="1.2.826.0.1.3680043.2.1143.7",
                bits=16, signed=True):
    explicit = syntax != IMPLICIT_LE
    sop = "%s.%d" % (series, instance)
    meta_body = (element(2, 1, "OB", b"\0\1") + element(2, 2, "UI", CT_STORAGE) +
                 element(2, 3, "UI", sop) + element(2, 0x10, "UI", syntax) +
                 element(2, 0x12, "UI", "1.2.826.0.1.3680043.2.1143.1"))
    meta = element(2, 0, "UL", struct.pack("<I", len(meta_body))) + meta_body
    n = rows * cols
    if bits == 16:
        pixels = b"".join(struct.pack("<h" if signed else "<H",
                                      ((i * 31 + instance * 100) % 2000) - (1024 if signed else 0))
                          for i in range(n))
    else:
        pixels = ramp(n)
    e = lambda g, el, vr, v: element(g, el, vr, v, explicit)
    us = lambda v: struct.pack("<H", v)
    ds = (e(8, 0x16, "UI", CT_STORAGE) + e(8, 0x18, "UI", sop) + e(8, 0x60, "CS", "CT") +
          e(8, 0x103E, "LO", "fuzz seed") + e(0x18, 0x50, "DS", "2") +
          e(0x20, 0xD, "UI", series + ".1") + e(0x20, 0xE, "UI", series) +
          e(0x20, 0x13, "IS", str(instance)) +
          e(0x20, 0x32, "DS", "-10\\-12.5\\%g" % z) +
          e(0x20, 0x37, "DS", "1\\0\\0\\0\\1\\0") + e(0x28, 2, "US", us(1)) +
          e(0x28, 4, "CS", "MONOCHROME2") + e(0x28, 0x10, "US", us(rows)) +
          e(0x28, 0x11, "US", us(cols)) + e(0x28, 0x30, "DS", "0.75\\0.5") +
          e(0x28, 0x100, "US", us(bits)) + e(0x28, 0x101, "US", us(bits if bits == 8 else 12)) +
          e(0x28, 0x102, "US", us(bits - 1 if bits == 8 else 11)) +
          e(0x28, 0x103, "US", us(1 if signed else 0)) +
          e(0x28, 0x1052, "DS", "-1024" if signed else "0") + e(0x28, 0x1053, "DS", "1") +
          e(0x7FE0, 0x10, "OW" if bits == 16 else "OB", pixels))
    return bytes(128) + b"DICM" + meta + ds


def gdcmconv(data, flag):
    """Re-encodes a DICOM file with gdcmconv (libgdcm-tools); None when it is unavailable."""
    if not shutil.which("gdcmconv"):
        return None
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = os.path.join(tmp, "in.dcm"), os.path.join(tmp, "out.dcm")
        with open(src, "wb") as f:
            f.write(data)
        r = subprocess.run(["gdcmconv", flag, src, dst], capture_output=True)
        if r.returncode != 0 or not os.path.exists(dst):
            print("make_fuzz_corpus: gdcmconv %s failed: %s" % (flag, r.stderr.decode()[:200]),
                  file=sys.stderr)
            return None
        with open(dst, "rb") as f:
            return f.read()


def dicom_seeds(out):
    single = dicom_slice(8, 12, 0.0, 1)
    put(out, "dicom", "explicit_le.dcm", single)
    put(out, "dicom", "implicit_le.dcm", dicom_slice(8, 12, 0.0, 1, IMPLICIT_LE))
    put(out, "dicom", "uint8.dcm", dicom_slice(6, 10, 0.0, 1, bits=8, signed=False))
    for flag, name in (("--j2k", "jpeg2000"), ("--jpegls", "jpegls"), ("--rle", "rle"),
                       ("--jpeg", "jpeg")):
        enc = gdcmconv(single, flag)
        if enc:
            put(out, "dicom", name + ".dcm", enc)
    for syntax, name in ((EXPLICIT_LE, "explicit"), (IMPLICIT_LE, "implicit")):
        slices = [dicom_slice(6, 8, 2.0 * k, k + 1, syntax) for k in range(3)]
        put(out, "dicom_series", name + ".seed", SPLIT.join(slices))
    j2k = [gdcmconv(dicom_slice(6, 8, 2.0 * k, k + 1), "--j2k") for k in range(2)]
    if all(j2k):
        put(out, "dicom_series", "jpeg2000.seed", SPLIT.join(j2k))


# --- Formats written by voxlight, nibabel and VTK -------------------------------------------------
def phantom_seeds(out, voxlight):
    with tempfile.TemporaryDirectory() as tmp:
        for name, size in (("kronander", 8), ("torso", 8), ("sphere", 8)):
            for ext, target in ((".nii", "nifti"), (".nii.gz", "nifti_gz"), (".mha", "metaimage"),
                                (".vti", "vti")):
                path = os.path.join(tmp, name + ext)
                subprocess.run([voxlight, "phantom", name, "--size", str(size), "-o", path],
                               check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                with open(path, "rb") as f:
                    data = f.read()
                put(out, target, name + ext, data)
                if ext == ".nii":  # the .nii.gz target compresses plain inputs itself
                    put(out, "nifti_gz", name + "-plain.nii", data)


def nibabel_seeds(out):
    try:
        import nibabel
        import numpy as np
    except ImportError:
        print("make_fuzz_corpus: nibabel missing (tools/setup.sh installs python3-nibabel); "
              "no NIfTI-2 seeds", file=sys.stderr)
        return
    with tempfile.TemporaryDirectory() as tmp:
        data = (np.arange(6 * 5 * 4, dtype=np.int16).reshape(6, 5, 4) * 11 - 300)
        affine = np.array([[-0.8, 0, 0, 10], [0, 0.8, 0, -20], [0, 0, 2.5, 5], [0, 0, 0, 1]])
        for cls, tag in ((nibabel.Nifti2Image, "nifti2"), (nibabel.Nifti1Image, "nifti1_qform")):
            img = cls(data, affine)
            img.header.set_qform(affine, code=1)
            img.header["descrip"] = b"voxlight fuzz seed"
            path = os.path.join(tmp, tag + ".nii")
            nibabel.save(img, path)
            with open(path, "rb") as f:
                raw = f.read()
            put(out, "nifti", tag + ".nii", raw)
            put(out, "nifti_gz", tag + "-plain.nii", raw)
        img = nibabel.Nifti1Image(np.linspace(0, 1, 60, dtype=np.float32).reshape(5, 4, 3),
                                  np.diag([1.0, 1.0, 1.0, 1.0]))
        img.header.set_slope_inter(2.0, -1.0)
        path = os.path.join(tmp, "float.nii")
        nibabel.save(img, path)
        with open(path, "rb") as f:
            put(out, "nifti", "float_scaled.nii", f.read())


def vtk_seeds(out):
    try:
        import vtk
    except ImportError:
        print("make_fuzz_corpus: python3-vtk9 missing; only voxlight's VTI seeds", file=sys.stderr)
        return
    img = vtk.vtkImageData()
    img.SetDimensions(6, 4, 3)
    img.SetSpacing(0.5, 1.0, 2.0)
    img.SetOrigin(-1, 2, 3)
    img.AllocateScalars(vtk.VTK_SHORT, 1)
    arr = img.GetPointData().GetScalars()
    for i in range(arr.GetNumberOfTuples()):
        arr.SetValue(i, (i * 97) % 1500 - 700)
    with tempfile.TemporaryDirectory() as tmp:
        for name, mode, compress, encode in (("ascii", 0, False, False),
                                              ("binary_inline", 1, False, True),
                                              ("appended_raw", 2, False, False),
                                              ("appended_base64", 2, False, True),
                                              ("appended_zlib", 2, True, False)):
            w = vtk.vtkXMLImageDataWriter()
            w.SetInputData(img)
            path = os.path.join(tmp, name + ".vti")
            w.SetFileName(path)
            w.SetDataMode(mode)
            if mode == 2:
                w.SetEncodeAppendedData(encode)
            if not compress:
                w.SetCompressorTypeToNone()
            w.Write()
            with open(path, "rb") as f:
                put(out, "vti", name + ".vti", f.read())


def scene_seeds(out):
    scenes = os.path.join(ROOT, "datasets", "scenes")
    for name in sorted(os.listdir(scenes)):
        if name.endswith(".json"):
            shutil.copy(os.path.join(scenes, name), os.path.join(out, "scene", name))


def session_seeds(out):
    # The example sessions; one referring to a scene file by a relative path finds none beside the
    # corpus, so an inline copy of each is added (the scene file's document put in its place).
    sessions = os.path.join(ROOT, "datasets", "sessions")
    for name in sorted(os.listdir(sessions)):
        if not name.endswith(".json"):
            continue
        with open(os.path.join(sessions, name)) as f:
            doc = json.load(f)
        shutil.copy(os.path.join(sessions, name), os.path.join(out, "session", name))
        if isinstance(doc.get("scene"), str):
            with open(os.path.join(sessions, doc["scene"])) as f:
                doc["scene"] = json.load(f)
            with open(os.path.join(out, "session", "inline-" + name), "w") as f:
                json.dump(doc, f, indent=1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outdir")
    ap.add_argument("--voxlight", default=os.path.join(ROOT, "build", "voxlight"),
                    help="a built voxlight CLI (for its phantom writer)")
    args = ap.parse_args()
    if not os.access(args.voxlight, os.X_OK):
        sys.exit("make_fuzz_corpus: %s is not an executable voxlight; build it first "
                 "(cmake --build --preset release --target voxlight) or pass --voxlight" %
                 args.voxlight)
    targets = ("nifti", "nifti_gz", "nrrd", "nrrd_detached", "metaimage", "metaimage_mhd", "vti",
               "raw", "dicom", "dicom_series", "scene", "session")
    for t in targets:
        shutil.rmtree(os.path.join(args.outdir, t), ignore_errors=True)
        os.makedirs(os.path.join(args.outdir, t))
    nrrd_seeds(args.outdir)
    meta_seeds(args.outdir)
    raw_seeds(args.outdir)
    dicom_seeds(args.outdir)
    phantom_seeds(args.outdir, args.voxlight)
    nibabel_seeds(args.outdir)
    vtk_seeds(args.outdir)
    scene_seeds(args.outdir)
    session_seeds(args.outdir)
    for t in targets:
        d = os.path.join(args.outdir, t)
        files = os.listdir(d)
        size = sum(os.path.getsize(os.path.join(d, f)) for f in files)
        print("%-14s %2d seeds, %6d bytes" % (t, len(files), size))


if __name__ == "__main__":
    main()
