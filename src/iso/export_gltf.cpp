// SPDX-License-Identifier: MIT
// glTF 2.0 binary export through Debian's tinygltf (shared library: no TINYGLTF_IMPLEMENTATION
// here). The layout and the node matrix are documented in export.h.
#include <tiny_gltf.h>

#include <limits>
#include <sstream>
#include <string>

#include "core/error.h"
#include "core/files.h"
#include "iso/export.h"

namespace voxlight::iso::detail {

namespace {

/// Appends `bytes` to buffer 0 as a new buffer view; returns the view's index.
int addView(tinygltf::Model& model, const void* bytes, std::size_t size, int target) {
    std::vector<unsigned char>& data = model.buffers[0].data;
    while (data.size() % 4) data.push_back(0);  // accessors need 4-byte alignment
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = data.size();
    view.byteLength = size;
    view.target = target;
    const auto* p = static_cast<const unsigned char*>(bytes);
    data.insert(data.end(), p, p + size);
    model.bufferViews.push_back(view);
    return int(model.bufferViews.size()) - 1;
}

int addAccessor(tinygltf::Model& model, int view, int componentType, int type, std::size_t count) {
    tinygltf::Accessor a;
    a.bufferView = view;
    a.componentType = componentType;
    a.type = type;
    a.count = count;
    model.accessors.push_back(a);
    return int(model.accessors.size()) - 1;
}

}  // namespace

void writeGlb(const Mesh& mesh, const std::filesystem::path& path, const ExportInfo& info) {
    const std::size_t nv = mesh.n_vertices(), nf = mesh.n_faces();
    std::vector<float> positions(3 * nv), normals(3 * nv), colours(3 * nv);
    std::vector<double> lo(3, std::numeric_limits<double>::max()),
        hi(3, std::numeric_limits<double>::lowest());
    for (const auto v : mesh.vertices()) {
        const std::size_t i = std::size_t(v.idx());
        for (int a = 0; a < 3; ++a) {
            positions[3 * i + a] = float(mesh.point(v)[a]);
            normals[3 * i + a] = float(mesh.normal(v)[a]);
            colours[3 * i + a] = std::clamp(mesh.color(v)[a], 0.f, 1.f);
            lo[a] = std::min(lo[a], double(positions[3 * i + a]));
            hi[a] = std::max(hi[a], double(positions[3 * i + a]));
        }
    }
    std::vector<std::uint32_t> indices;
    indices.reserve(3 * nf);
    for (const auto f : mesh.faces())
        for (const auto v : mesh.fv_range(f)) indices.push_back(std::uint32_t(v.idx()));

    tinygltf::Model model;
    model.asset.version = "2.0";
    model.asset.generator = "voxlight";
    tinygltf::Value::Object extras;
    for (const auto& line : commentLines(info, "COLOR_0 is linear RGB (glTF)"))
        extras[extras.empty() ? "description" : "note" + std::to_string(extras.size())] =
            tinygltf::Value(line);
    extras["units"] = tinygltf::Value(std::string("mm"));
    extras["frame"] = tinygltf::Value(std::string("LPS"));
    extras["isovalue"] = tinygltf::Value(info.isovalue);
    extras["node_matrix"] = tinygltf::Value(std::string(
        "node 0 maps vertex data (mm, LPS) to glTF metres: X = left, Y = superior, Z = anterior"));
    model.asset.extras = tinygltf::Value(extras);

    model.buffers.resize(1);
    const int pos = addAccessor(model,
                                addView(model, positions.data(), positions.size() * sizeof(float),
                                        TINYGLTF_TARGET_ARRAY_BUFFER),
                                TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, nv);
    model.accessors[pos].minValues = lo;
    model.accessors[pos].maxValues = hi;
    const int nrm = addAccessor(model,
                                addView(model, normals.data(), normals.size() * sizeof(float),
                                        TINYGLTF_TARGET_ARRAY_BUFFER),
                                TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, nv);
    const int col = addAccessor(model,
                                addView(model, colours.data(), colours.size() * sizeof(float),
                                        TINYGLTF_TARGET_ARRAY_BUFFER),
                                TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, nv);
    const int idx =
        addAccessor(model,
                    addView(model, indices.data(), indices.size() * sizeof(std::uint32_t),
                            TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                    TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, indices.size());

    tinygltf::Material material;
    material.name = "isosurface";
    material.pbrMetallicRoughness.baseColorFactor = {1.0, 1.0, 1.0, 1.0};
    material.pbrMetallicRoughness.metallicFactor = 0.0;
    material.pbrMetallicRoughness.roughnessFactor = 1.0;
    model.materials.push_back(material);

    tinygltf::Primitive prim;
    prim.attributes["POSITION"] = pos;
    prim.attributes["NORMAL"] = nrm;
    prim.attributes["COLOR_0"] = col;
    prim.indices = idx;
    prim.material = 0;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    tinygltf::Mesh gmesh;
    gmesh.name = "isosurface";
    gmesh.primitives.push_back(prim);
    model.meshes.push_back(gmesh);

    tinygltf::Node node;
    node.name = "patient_lps_mm";
    node.mesh = 0;
    // Column-major 4×4: X = 0.001·x, Y = 0.001·z, Z = −0.001·y.
    const double s = 0.001;
    node.matrix = {s, 0, 0, 0, 0, 0, -s, 0, 0, s, 0, 0, 0, 0, 0, 1};
    model.nodes.push_back(node);
    tinygltf::Scene scene;
    scene.nodes.push_back(0);
    model.scenes.push_back(scene);
    model.defaultScene = 0;

    // Serialised in memory, then written here with every write checked: tinygltf's file writer
    // reports success over a short file when a write fails (a full disk gave a 12-KB .glb).
    tinygltf::TinyGLTF writer;
    std::ostringstream bytes;
    if (!writer.WriteGltfSceneToStream(&model, bytes, false, true))
        throw InputError(path.string(), "output", "cannot serialise the glTF model",
                         "report this with the mesh's size");
    core::writeWholeFile(path, bytes.str());
}

}  // namespace voxlight::iso::detail
