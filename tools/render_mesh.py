#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Render exported isosurface meshes (voxlight iso ... -o X.ply|.obj) side by side, seen from the
patient's front, to look at them: one viewport per mesh, vertex colours as stored, VTK's headlight.

usage: xvfb-run -a /usr/bin/python3 tools/render_mesh.py OUT.png MESH [MESH ...] [--size W H]
[--unlit [INDEX ...]] [--azimuth DEG] [--elevation DEG]
--unlit (all meshes, or those at the 0-based indices given) shows the stored vertex colours as they are (no headlight): how a mesh with light baked in by
`voxlight iso --bake` looks in a viewer that draws vertex colours flat. --azimuth turns the camera about
the superior axis (0 = anterior view, 90 = from the patient's left); --elevation raises it toward
superior (90 = looking down from above, e.g. at the cap of an axial cut).
Meshes are in mm, patient LPS (src/iso/export.h): the camera looks along +y (from anterior) with
+z (superior) up. Needs Debian's python3-vtk9 (tools/setup.sh).
"""
import argparse
import math

from vtkmodules.vtkIOGeometry import vtkOBJReader
from vtkmodules.vtkIOImage import vtkPNGWriter
from vtkmodules.vtkIOPLY import vtkPLYReader
from vtkmodules.vtkRenderingCore import (vtkActor, vtkPolyDataMapper, vtkRenderer,
                                         vtkRenderWindow, vtkWindowToImageFilter)
import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (registers the OpenGL back-end)


def read(path):
    reader = vtkPLYReader() if path.lower().endswith(".ply") else vtkOBJReader()
    reader.SetFileName(path)
    reader.Update()
    return reader.GetOutput()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("meshes", nargs="+")
    ap.add_argument("--size", nargs=2, type=int, default=[400, 400], help="per viewport")
    ap.add_argument("--unlit", nargs="*", type=int, default=None, metavar="INDEX",
                    help="vertex colours as stored, no lighting: every mesh, or those at the given "
                         "0-based indices")
    ap.add_argument("--azimuth", type=float, default=0.0, help="degrees about +z from anterior")
    ap.add_argument("--elevation", type=float, default=0.0,
                    help="degrees above the axial plane (toward superior)")
    a = ap.parse_args()
    n = len(a.meshes)
    window = vtkRenderWindow()
    window.SetOffScreenRendering(1)
    window.SetSize(a.size[0] * n, a.size[1])
    for i, path in enumerate(a.meshes):
        mesh = read(path)
        mapper = vtkPolyDataMapper()
        mapper.SetInputData(mesh)
        mapper.SetScalarModeToUsePointData()
        mapper.SetColorModeToDirectScalars()
        actor = vtkActor()
        actor.SetMapper(mapper)
        if a.unlit is not None and (not a.unlit or i in a.unlit):
            actor.GetProperty().SetLighting(False)
        ren = vtkRenderer()
        ren.SetViewport(i / n, 0, (i + 1) / n, 1)
        ren.SetBackground(0.08, 0.08, 0.1)
        ren.AddActor(actor)
        b = mesh.GetBounds()
        c = [(b[0] + b[1]) / 2, (b[2] + b[3]) / 2, (b[4] + b[5]) / 2]
        cam = ren.GetActiveCamera()
        cam.SetFocalPoint(*c)
        az = math.radians(a.azimuth)
        # anterior is −y in LPS; +azimuth turns toward the patient's left (+x)
        el = math.radians(max(-89.0, min(89.0, a.elevation)))
        cam.SetPosition(c[0] + 1000.0 * math.sin(az) * math.cos(el),
                        c[1] - 1000.0 * math.cos(az) * math.cos(el), c[2] + 1000.0 * math.sin(el))
        cam.SetViewUp(0, 0, 1)
        ren.ResetCamera()
        cam.Zoom(1.15)
        window.AddRenderer(ren)
    window.Render()
    grab = vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.Update()
    writer = vtkPNGWriter()
    writer.SetFileName(a.out)
    writer.SetInputConnection(grab.GetOutputPort())
    writer.Write()


if __name__ == "__main__":
    main()
