// SPDX-License-Identifier: MIT
// The VTK module of iso/ (flying_edges_module.h): vtkFlyingEdges3D on a zero-copy view of the
// volume's stored voxels, in index space.
#include "iso/flying_edges_module.h"

#include <vtkCallbackCommand.h>
#include <vtkCellArray.h>
#include <vtkFloatArray.h>
#include <vtkFlyingEdges3D.h>
#include <vtkImageData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkShortArray.h>
#include <vtkSmartPointer.h>
#include <vtkUnsignedCharArray.h>
#include <vtkUnsignedShortArray.h>

#include <algorithm>
#include <cstring>

namespace voxlight::iso {

namespace {

/// The volume's buffer as a VTK array that does not own (nor free) it.
template <class Array, class T>
vtkSmartPointer<vtkDataArray> wrap(const core::Volume& volume) {
    auto a = vtkSmartPointer<Array>::New();
    // VTK's API takes a mutable pointer; flying edges only reads it.
    a->SetArray(const_cast<T*>(volume.dataAs<T>()), vtkIdType(volume.voxelCount()), 1);
    a->SetName("values");
    return a;
}

vtkSmartPointer<vtkDataArray> wrapVolume(const core::Volume& volume) {
    switch (volume.type()) {
        case core::VoxelType::UInt8:
            return wrap<vtkUnsignedCharArray, std::uint8_t>(volume);
        case core::VoxelType::Int16:
            return wrap<vtkShortArray, std::int16_t>(volume);
        case core::VoxelType::UInt16:
            return wrap<vtkUnsignedShortArray, std::uint16_t>(volume);
        case core::VoxelType::Float32:
            return wrap<vtkFloatArray, float>(volume);
    }
    throw InternalError("unknown voxel type");
}

struct ProgressBridge {
    const core::Progress* progress = nullptr;
    bool cancelled = false;
};

void onProgress(vtkObject* caller, unsigned long, void* clientData, void* callData) {
    auto* bridge = static_cast<ProgressBridge*>(clientData);
    auto* filter = static_cast<vtkAlgorithm*>(caller);
    // Never throw through VTK's frames: raise its abort flag and throw after Update().
    if (bridge->progress->cancelled()) {
        bridge->cancelled = true;
        filter->SetAbortExecute(1);
        return;
    }
    bridge->progress->report("flying edges", *static_cast<double*>(callData));
}

template <class Ids>
void copyTriangles(const Ids* ids, std::size_t n, std::vector<std::uint32_t>& out) {
    out.resize(n);
    for (std::size_t i = 0; i < n; ++i) out[i] = std::uint32_t(ids[i]);
}

fe_module::Soup flyingEdges(const core::Volume& volume, double storedIsovalue,
                            const core::Progress& progress) {
    const glm::ivec3 d = volume.dims();
    vtkNew<vtkImageData> image;
    image->SetDimensions(d.x, d.y, d.z);
    image->SetSpacing(1.0, 1.0, 1.0);
    image->SetOrigin(0.0, 0.0, 0.0);
    image->GetPointData()->SetScalars(wrapVolume(volume));

    vtkNew<vtkFlyingEdges3D> fe;
    fe->SetInputData(image);
    fe->SetValue(0, storedIsovalue);
    fe->ComputeNormalsOff();
    fe->ComputeGradientsOff();
    fe->ComputeScalarsOff();
    fe->InterpolateAttributesOff();
    ProgressBridge bridge{&progress};
    vtkNew<vtkCallbackCommand> callback;
    callback->SetCallback(onProgress);
    callback->SetClientData(&bridge);
    fe->AddObserver(vtkCommand::ProgressEvent, callback);
    progress.report("flying edges", 0.0);
    fe->Update();
    if (bridge.cancelled) throw CancelledError();

    fe_module::Soup soup;
    vtkPolyData* out = fe->GetOutput();
    if (out->GetNumberOfPoints() == 0) return soup;
    vtkDataArray* pts = out->GetPoints()->GetData();
    const std::size_t np = std::size_t(pts->GetNumberOfTuples());
    soup.points.resize(3 * np);
    if (auto* f = vtkFloatArray::SafeDownCast(pts)) {
        std::memcpy(soup.points.data(), f->GetPointer(0), 3 * np * sizeof(float));
    } else {
        for (std::size_t i = 0; i < np; ++i) {
            double p[3];
            pts->GetTuple(vtkIdType(i), p);
            for (int a = 0; a < 3; ++a) soup.points[3 * i + a] = float(p[a]);
        }
    }
    vtkCellArray* polys = out->GetPolys();
    const std::size_t nc = std::size_t(polys->GetNumberOfCells());
    const std::size_t nconn = std::size_t(polys->GetNumberOfConnectivityIds());
    VL_CHECK_EQ(nconn, 3 * nc);  // flying edges emits triangles only
    if (polys->IsStorage64Bit())
        copyTriangles(polys->GetConnectivityArray64()->GetPointer(0), nconn, soup.triangles);
    else
        copyTriangles(polys->GetConnectivityArray32()->GetPointer(0), nconn, soup.triangles);
    progress.report("flying edges", 1.0);
    return soup;
}

const fe_module::Api kApi{fe_module::kAbiVersion, &flyingEdges};

}  // namespace

}  // namespace voxlight::iso

extern "C" __attribute__((visibility("default"))) const void* voxlight_iso_vtk_module() {
    return &voxlight::iso::kApi;
}
