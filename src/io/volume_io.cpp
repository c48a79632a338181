// SPDX-License-Identifier: MIT
// Volume reading and writing through VTK (and DICOM through the GDCM module). Built into the module
// libvoxlight_volume_vtk.so, not into io: the io functions of volume_io.h forward here
// (volume_io_loader.cpp, volume_module.h).
#include "io/volume_io.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <vtkCommand.h>
#include <vtkDataArray.h>
#include <vtkImageData.h>
#include <vtkImageReader2.h>
#include <vtkInformation.h>
#include <vtkLogger.h>
#include <vtkMatrix3x3.h>
#include <vtkMatrix4x4.h>
#include <vtkMetaImageReader.h>
#include <vtkMetaImageWriter.h>
#include <vtkNIFTIImageHeader.h>
#include <vtkNIFTIImageReader.h>
#include <vtkNIFTIImageWriter.h>
#include <vtkNew.h>
#include <vtkNrrdReader.h>
#include <vtkObjectFactory.h>
#include <vtkOutputWindow.h>
#include <vtkPointData.h>
#include <vtkSmartPointer.h>
#include <vtkStreamingDemandDrivenPipeline.h>
#include <vtkType.h>
#include <vtkXMLImageDataReader.h>
#include <vtkXMLImageDataWriter.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <mutex>
#include <sstream>

#include "core/files.h"
#include "core/text.h"
#include "io/child_process.h"
#include "io/dicom_series.h"
#include "io/module_loader.h"
#include "io/nrrd_header.h"
#include "io/volume_module.h"

namespace voxlight::io {

namespace fs = std::filesystem;
using core::Geometry;
using core::Volume;
using core::VoxelType;

namespace {

// ---------------------------------------------------------------------------------------------------------------
// VTK diagnostics: VTK reports problems through vtkErrorMacro → an observer or the global output
// window. We route both into a per-read list so that a reader's complaint becomes one InputError
// instead of text on stderr.

class CaptureOutputWindow : public vtkOutputWindow {
  public:
    static CaptureOutputWindow* New();
    vtkTypeMacro(CaptureOutputWindow, vtkOutputWindow);
    void DisplayText(const char* text) override {
        std::lock_guard<std::mutex> lock(mutex_);
        if (text) messages_.emplace_back(text);
    }
    std::vector<std::string> take() {
        std::lock_guard<std::mutex> lock(mutex_);
        return std::exchange(messages_, {});
    }

  private:
    std::mutex mutex_;
    std::vector<std::string> messages_;
};
vtkStandardNewMacro(CaptureOutputWindow);

CaptureOutputWindow& captureWindow() {
    static vtkSmartPointer<CaptureOutputWindow> w = [] {
        auto p = vtkSmartPointer<CaptureOutputWindow>::New();
        vtkOutputWindow::SetInstance(p);
        // vtkExecutive also logs pipeline failures through vtkLogger straight to stderr; the
        // reader's own error (captured above) is the message users need.
        vtkLogger::SetStderrVerbosity(vtkLogger::VERBOSITY_OFF);
        return p;
    }();
    return *w;
}

/// Collects a reader's errors, forwards its progress and aborts it when the user cancels.
class ReaderObserver : public vtkCommand {
  public:
    static ReaderObserver* New() { return new ReaderObserver; }
    void Execute(vtkObject* caller, unsigned long event, void* data) override {
        if (event == vtkCommand::ErrorEvent && data)
            errors.emplace_back(static_cast<const char*>(data));
        if (event == vtkCommand::ProgressEvent && data && progress) {
            // The reader's loop tests AbortExecute at its next step (NIfTI: every 2 % of its
            // rows; NRRD raw data: every 2 % of its slices' rows; VTI: every block of data).
            // No exception may unwind through VTK's frames: a flag raised between the check and
            // report() aborts the same way.
            try {
                if (!progress->cancelled()) {
                    progress->report("read", *static_cast<double*>(data));
                    return;
                }
            } catch (const CancelledError&) {
            }
            cancelled = true;
            if (auto* alg = vtkAlgorithm::SafeDownCast(caller)) alg->SetAbortExecute(1);
        }
    }
    std::vector<std::string> errors;
    const core::Progress* progress = nullptr;
    bool cancelled = false;
};

/// First line of a VTK message without the "ERROR: In file, line N / vtkClass (0x...): " preamble.
std::string cleanVtkMessage(std::string m) {
    const auto pos = m.find("): ");
    if (pos != std::string::npos && m.find("ERROR: In") != std::string::npos) m = m.substr(pos + 3);
    while (!m.empty() && (m.back() == '\n' || m.back() == ' ')) m.pop_back();
    std::replace(m.begin(), m.end(), '\n', ' ');
    return m;
}

/// Runs `update`, turning any VTK error into an InputError for `path`.
void runVtkChecked(vtkAlgorithm* alg, const fs::path& path, const std::string& what,
                   const std::function<void()>& update,
                   const core::Progress& progress = core::Progress::none()) {
    captureWindow().take();
    vtkNew<ReaderObserver> obs;
    obs->progress = &progress;
    const unsigned long tag = alg->AddObserver(vtkCommand::ErrorEvent, obs);
    const unsigned long tagP = alg->AddObserver(vtkCommand::ProgressEvent, obs);
    try {
        update();
    } catch (const CancelledError&) {
        throw;
    } catch (const std::exception& e) {  // some VTK readers throw on malformed input
        alg->RemoveObserver(tag);
        alg->RemoveObserver(tagP);
        throw InputError(path.string(), what, std::string("could not be read: ") + e.what(),
                         "check that the file is complete and not corrupt");
    }
    alg->RemoveObserver(tag);
    alg->RemoveObserver(tagP);
    if (obs->cancelled) throw CancelledError();
    std::vector<std::string> errs = obs->errors;
    for (auto& m : captureWindow().take())
        if (m.find("ERROR") != std::string::npos) errs.push_back(m);
    if (!errs.empty() || alg->GetErrorCode() != 0) {
        std::string msg = errs.empty() ? std::string("VTK reported error code ") +
                                             std::to_string(alg->GetErrorCode())
                                       : cleanVtkMessage(errs.front());
        throw InputError(path.string(), what, "could not be read: " + msg,
                         "check that the file is complete and not corrupt");
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Size checks before any allocation.

/// Deflate (zlib, gzip) expands at most 1032:1: compressed data claiming more bytes than its size
/// times this (plus kDeflateSlackBytes for headers and tiny inputs) cannot be what it says.
constexpr std::uint64_t kMaxDeflateRatio = 1032;
constexpr std::uint64_t kDeflateSlackBytes = std::uint64_t(1) << 16;

void checkExtent(const int ext[6], int components, const fs::path& path) {
    std::ostringstream dims;
    std::uint64_t voxels = 1;
    bool bad = false;
    for (int a = 0; a < 3; ++a) {
        const long long n = (long long)ext[2 * a + 1] - ext[2 * a] + 1;
        dims << (a ? "x" : "") << n;
        if (n < 1 || n > core::kMaxDim) bad = true;
        if (!bad) voxels *= std::uint64_t(n);
    }
    if (bad && dims.str().find('-') != std::string::npos)
        throw InputError(path.string(), "dims",
                         "declares invalid dimensions (the reader made " + dims.str() +
                             " of them: a size is missing, zero or too large to represent)",
                         "the header is corrupt; check its sizes/dims field");
    if (bad || voxels > core::kMaxVoxels)
        throw InputError(path.string(), "dims",
                         "declares " + dims.str() + " voxels, outside the supported range (1.." +
                             std::to_string(core::kMaxDim) + " per axis, at most " +
                             std::to_string(core::kMaxVoxels) + " voxels)",
                         "the header is corrupt or the volume must be cropped/downsampled first");
    if (components != 1)
        throw InputError(path.string(), "components",
                         "has " + std::to_string(components) +
                             " components per voxel; voxlight renders scalar volumes",
                         "extract one channel first");
}

// ---------------------------------------------------------------------------------------------------------------
// vtkImageData → Volume, converting types that voxlight does not store natively.

template <class Src, class Dst>
void convertCopy(const Src* src, Dst* dst, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) dst[i] = Dst(src[i]);
}

/// The image's voxel array: its active point scalars, else its first point data array;
/// InputError when it has none.
vtkDataArray* imageScalars(vtkImageData* img, const fs::path& path) {
    vtkDataArray* scalars = img->GetPointData()->GetScalars();
    if (!scalars && img->GetPointData()->GetNumberOfArrays() > 0)
        scalars = img->GetPointData()->GetArray(0);
    if (!scalars)
        throw InputError(path.string(), "scalars", "holds no point data array",
                         "is this an image file?");
    return scalars;
}

Volume fromImageData(vtkImageData* img, const fs::path& path, Geometry g) {
    int ext[6];
    img->GetExtent(ext);
    vtkDataArray* scalars = imageScalars(img, path);
    checkExtent(ext, scalars->GetNumberOfComponents(), path);
    g.dims = {ext[1] - ext[0] + 1, ext[3] - ext[2] + 1, ext[5] - ext[4] + 1};
    const std::size_t n = std::size_t(g.voxelCount());
    if (std::size_t(scalars->GetNumberOfTuples()) != n)
        throw InputError(path.string(), "data",
                         "holds " + std::to_string(scalars->GetNumberOfTuples()) + " values for " +
                             std::to_string(n) + " voxels",
                         "the file is truncated or inconsistent");

    const int vt = scalars->GetDataType();
    auto make = [&](VoxelType t) { return Volume(g, t); };
    // Native types: adopt VTK's array without copying (halves peak memory for large CTs).
    auto adopt = [&](VoxelType t) {
        scalars->Register(nullptr);
        std::shared_ptr<std::byte> storage(static_cast<std::byte*>(scalars->GetVoidPointer(0)),
                                           [scalars](std::byte*) { scalars->UnRegister(nullptr); });
        return Volume(g, t, std::move(storage));
    };
    switch (vt) {
        case VTK_UNSIGNED_CHAR:
            return adopt(VoxelType::UInt8);
        case VTK_SHORT:
            return adopt(VoxelType::Int16);
        case VTK_UNSIGNED_SHORT:
            return adopt(VoxelType::UInt16);
        case VTK_FLOAT:
            return adopt(VoxelType::Float32);
        case VTK_CHAR:
        case VTK_SIGNED_CHAR: {
            Volume v = make(VoxelType::Int16);
            convertCopy(static_cast<const signed char*>(scalars->GetVoidPointer(0)),
                        v.dataAs<std::int16_t>(), n);
            return v;
        }
        default:
            break;
    }
    // Wider types: keep integers exact in int16/uint16 when their range allows, else float32.
    double range[2];
    scalars->GetRange(range, 0);
    const bool integral = vt == VTK_INT || vt == VTK_UNSIGNED_INT || vt == VTK_LONG ||
                          vt == VTK_UNSIGNED_LONG || vt == VTK_LONG_LONG ||
                          vt == VTK_UNSIGNED_LONG_LONG || vt == VTK_ID_TYPE;
    if (!integral && vt != VTK_DOUBLE)
        throw InputError(
            path.string(), "type",
            std::string("voxel type ") + scalars->GetDataTypeAsString() + " is not supported",
            "convert to int16, uint16 or float32");
    VoxelType target = VoxelType::Float32;
    if (integral && range[0] >= -32768 && range[1] <= 32767)
        target = VoxelType::Int16;
    else if (integral && range[0] >= 0 && range[1] <= 65535)
        target = VoxelType::UInt16;
    Volume v = make(target);
    for (std::size_t i = 0; i < n; ++i) {
        const double x = scalars->GetComponent(vtkIdType(i), 0);
        switch (target) {
            case VoxelType::Int16:
                v.dataAs<std::int16_t>()[i] = std::int16_t(x);
                break;
            case VoxelType::UInt16:
                v.dataAs<std::uint16_t>()[i] = std::uint16_t(x);
                break;
            default:
                v.dataAs<float>()[i] = float(x);
                break;
        }
    }
    return v;
}

/// Orthonormal check of a direction matrix read from a file (sheared or degenerate → InputError).
void checkDirection(const glm::dmat3& d, const fs::path& path, const std::string& field) {
    constexpr double kOrthoTol =
        1e-3;  // headers store cosines to ~6 digits; shear of 0.06° still passes
    for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r)
            if (!std::isfinite(d[c][r]))
                throw InputError(path.string(), field, "holds a NaN or infinite orientation value",
                                 "repair the header's " + field + " (e.g. with nibabel)");
    const glm::dmat3 g = glm::transpose(d) * d;
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c)
            if (!std::isfinite(g[c][r]) || std::abs(g[c][r] - (r == c ? 1.0 : 0.0)) > kOrthoTol)
                throw InputError(path.string(), field,
                                 "describes a sheared or degenerate grid (axes not orthonormal), "
                                 "e.g. gantry tilt",
                                 "reslice the volume to an orthogonal grid first");
}

// ---------------------------------------------------------------------------------------------------------------
// Readers.

struct Reader {
    std::string name;
    std::vector<std::string> extensions;  // lower case, with dot; ".nii.gz" matches before ".gz"
    std::function<bool(const fs::path&)> canRead;
    std::function<Volume(const fs::path&, const ReadOptions&, const core::Progress&)> read;
};

std::string lowerName(const fs::path& p) {
    std::string s = p.filename().string();
    std::transform(s.begin(), s.end(), s.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}
bool hasExtension(const fs::path& p, const std::vector<std::string>& exts) {
    const std::string s = lowerName(p);
    for (const auto& e : exts)
        if (s.size() > e.size() && s.compare(s.size() - e.size(), e.size(), e) == 0) return true;
    return false;
}

// ---------------------------------------------------------------------------------------------------------------
// Readers whose data read has no progress events to abort on (MetaIO reads all voxels in one call;
// VTK's NRRD reader inflates gzip data in one gzread and parses ascii in one loop) run it in a
// forked child when the caller can cancel: the parent polls the cancel flag and kills the child,
// so Ctrl-C is honoured within a poll interval however large the file. The voxels come back
// through a memfd the parent maps; VTK's errors and what MetaIO printed on std::cerr come back as
// text and are judged as an in-process read would judge them. A crash of the reader becomes an
// InputError instead of ending voxlight.

/// How often the parent looks at the cancel flag and the child's progress.
constexpr int kChildPollMs = 50;

/// Keeps a shared_ptr alive as long as the VTK object it observes (released on its deletion).
class KeepAlive : public vtkCommand {
  public:
    static KeepAlive* New() { return new KeepAlive; }
    void Execute(vtkObject*, unsigned long, void*) override {}
    std::shared_ptr<void> held;
};

void putField(std::string& out, const std::string& s) {
    const std::uint32_t n = std::uint32_t(s.size());
    out.append(reinterpret_cast<const char*>(&n), sizeof n);
    out += s;
}
std::string takeField(const std::string& in, std::size_t& at) {
    std::uint32_t n = 0;
    if (at + sizeof n > in.size()) return {};
    std::memcpy(&n, in.data() + at, sizeof n);
    at += sizeof n;
    n = std::uint32_t(std::min<std::size_t>(n, in.size() - at));
    std::string out = in.substr(at, n);
    at += n;
    return out;
}

[[noreturn]] void systemFailure(const fs::path& path, const char* what) {
    throw InputError(
        path.string(), "data",
        std::string("cannot start the reader process: ") + what + ": " + std::strerror(errno),
        "check the system's limits on processes and memory");
}

/// Starts a reading child: a memfd for its voxels (child.mem), a pipe for its messages
/// (child.msg), then fork; the child runs `body(msgFd)`, which never returns.
template <class Body>
void forkReader(ChildProcess& child, const fs::path& path, Body&& body) {
    child.mem = ::memfd_create("voxlight-read", MFD_CLOEXEC);
    if (child.mem < 0) systemFailure(path, "memfd_create");
    int pipeFds[2];
    if (::pipe2(pipeFds, O_CLOEXEC) != 0) systemFailure(path, "pipe");
    child.msg = pipeFds[0];
    detail::awaitModuleLoads();  // no fork during a dlopen (module_loader.h)
    std::fflush(nullptr);        // nothing buffered is written twice (the loader may have printed)
    child.pid = ::fork();
    if (child.pid < 0) {
        ::close(pipeFds[1]);
        systemFailure(path, "fork");
    }
    if (child.pid == 0) {
        ::close(pipeFds[0]);
        body(pipeFds[1]);
    }
    ::close(pipeFds[1]);
}

/// The child's voxels (`values` of VTK type `type`, `comps` per tuple) mapped from its memfd as a
/// VTK array that keeps the mapping alive.
vtkSmartPointer<vtkDataArray> mappedScalars(int memFd, int type, int comps, std::size_t values) {
    const std::size_t bytes = values * std::size_t(vtkDataArray::GetDataTypeSize(type));
    struct stat st {};
    if (::fstat(memFd, &st) != 0 || std::uint64_t(st.st_size) != bytes)
        throw InternalError("volume reader: the child's voxel buffer has the wrong size");
    void* p =
        bytes ? ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, memFd, 0) : nullptr;
    if (p == MAP_FAILED) throw std::bad_alloc();
    const std::shared_ptr<void> mapping(p, [bytes](void* q) {
        if (q) ::munmap(q, bytes);
    });
    vtkSmartPointer<vtkDataArray> scalars;
    scalars.TakeReference(vtkDataArray::CreateDataArray(type));
    if (!scalars) throw InternalError("volume reader: VTK type " + std::to_string(type));
    scalars->SetNumberOfComponents(comps);
    scalars->SetVoidArray(p, vtkIdType(values), 1);  // 1: VTK must not free it
    vtkNew<KeepAlive> keep;
    keep->held = mapping;
    scalars->AddObserver(vtkCommand::DeleteEvent, keep);
    return scalars;
}

/// Sends `msg` whole through `fd` (the child's last act).
void sendAll(int fd, const std::string& msg) {
    const char* p = msg.data();
    std::size_t left = msg.size();
    while (left > 0) {
        const ssize_t w = ::write(fd, p, left);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) break;
        p += w, left -= std::size_t(w);
    }
}

/// Copies a child's voxels into its memfd (bad_alloc when the memfd cannot grow or map).
void copyIntoMemfd(int memFd, const void* data, std::size_t bytes) {
    if (bytes == 0) return;
    if (::ftruncate(memFd, off_t(bytes)) != 0) throw std::bad_alloc();
    void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, memFd, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    std::memcpy(p, data, bytes);
    ::munmap(p, bytes);
}

/// The child: read the data, copy the voxels into `memFd`, send one message ('V' done, 'E'
/// InputError fields, 'X' another exception) followed by what was printed on std::cerr.
[[noreturn]] void readInChild(vtkImageReader2* r, const fs::path& path, std::size_t bytes,
                              int msgFd, int memFd) {
    becomeReaderChild();
    std::ostringstream printed;
    std::cerr.rdbuf(printed.rdbuf());  // the parent's capture (if any) is the parent's
    std::string msg;
    try {
        runVtkChecked(r, path, "data", [&] { r->Update(); });
        vtkDataArray* scalars = r->GetOutput()->GetPointData()->GetScalars();
        if (!scalars ||
            std::size_t(scalars->GetNumberOfValues()) * std::size_t(scalars->GetDataTypeSize()) !=
                bytes)
            throw InternalError("the reader's output does not have the size of its header");
        copyIntoMemfd(memFd, scalars->GetVoidPointer(0), bytes);
        msg = "V";
    } catch (const InputError& e) {
        msg = "E";
        for (const std::string* f : {&e.source(), &e.field(), &e.problem(), &e.fix()})
            putField(msg, *f);
    } catch (const std::bad_alloc&) {
        msg = "X";
        putField(msg, "out of memory");
    } catch (const std::exception& e) {
        msg = "X";
        putField(msg, e.what());
    }
    putField(msg, printed.str());
    sendAll(msgFd, msg);
    ::_exit(0);  // no atexit handlers, no flush of the parent's stdio buffers
}

/// The parent's side of a reading child: polls its message pipe (and the cancel flag: a
/// CancelledError leaves the guard to kill the child) until it closes, reaps it, and throws what
/// the child reported — its InputError, another exception (InternalError), an out-of-memory
/// ('M', an InputError: the file asks for more than the child may use) or an abnormal end (a
/// crash: InputError naming the signal). Returns the message of a 'V' (done) child; `at` is set
/// past its kind byte. `expectedBytes` (file bytes the read takes, 0 if unknown) turns the
/// child's read count into progress.
std::string awaitChild(ChildProcess& child, const fs::path& path, const core::Progress& progress,
                       std::uint64_t expectedBytes, std::size_t& at) {
    std::string msg;
    progress.report("read", 0.0);
    for (;;) {
        pollfd fd{child.msg, POLLIN, 0};
        const int n = ::poll(&fd, 1, kChildPollMs);
        progress.checkCancel();  // CancelledError: the guard kills the child
        if (n < 0 && errno != EINTR) systemFailure(path, "poll");
        if (n > 0) {
            char buf[4096];
            const ssize_t got = ::read(child.msg, buf, sizeof buf);
            if (got > 0) {
                msg.append(buf, std::size_t(got));
                continue;
            }
            if (got == 0 || (errno != EINTR && errno != EAGAIN)) break;  // the child is done
        } else if (expectedBytes > 0) {
            progress.report("read",
                            std::min(0.99, double(child.bytesRead()) / double(expectedBytes)));
        }
    }
    const int status = child.wait();
    progress.checkCancel();

    at = 1;
    const char kind = msg.empty() ? '\0' : msg[0];
    if (kind == 'E') {
        const std::string source = takeField(msg, at), field = takeField(msg, at),
                          problem = takeField(msg, at), fix = takeField(msg, at);
        std::cerr << takeField(msg, at);  // into the caller's capture, as an in-process read
        throw InputError(source, field, problem, fix);
    }
    if (kind == 'M')
        throw InputError(path.string(), "data",
                         "could not be read: the reader asked for more memory than the file's "
                         "sizes justify (" +
                             takeField(msg, at) + ")",
                         "the file is damaged, or its sizes or compression headers were edited");
    if (kind == 'X') throw InternalError("volume reader: " + takeField(msg, at));
    if (kind != 'V' && WIFEXITED(status) && WEXITSTATUS(status) == kChildOverBudgetStatus)
        throw InputError(path.string(), "data",
                         "could not be read: the reader asked for more memory than the file's "
                         "sizes justify (over its budget)",
                         "the file is damaged, or its sizes or compression headers were edited");
    if (kind != 'V') {
        std::string why = "the reader ended abnormally";
        if (WIFSIGNALED(status))
            why = "the reader crashed with signal " + std::to_string(WTERMSIG(status)) + " (" +
                  strsignal(WTERMSIG(status)) + ")";
        else if (WIFEXITED(status))
            why = "the reader exited with status " + std::to_string(WEXITSTATUS(status));
        throw InputError(path.string(), "data", "could not be read: " + why,
                         "check that the file is complete and not corrupt");
    }
    return msg;
}

/// Runs `r`'s data read (after UpdateInformation) in a child; the output image, its scalars
/// mapped from the child's memfd. `expectedBytes` (the bytes the read will take from files, 0 if
/// unknown) turns the child's read count into progress.
vtkSmartPointer<vtkImageData> readContained(vtkImageReader2* r, const fs::path& path,
                                            std::uint64_t expectedBytes,
                                            const core::Progress& progress) {
    int ext[6];
    r->GetDataExtent(ext);
    const int comps = r->GetNumberOfScalarComponents();
    const std::size_t values = std::size_t(ext[1] - ext[0] + 1) * std::size_t(ext[3] - ext[2] + 1) *
                               std::size_t(ext[5] - ext[4] + 1) * std::size_t(comps);
    const std::size_t bytes =
        values * std::size_t(vtkDataArray::GetDataTypeSize(r->GetDataScalarType()));
    ChildProcess child;
    forkReader(child, path, [&](int msgFd) { readInChild(r, path, bytes, msgFd, child.mem); });
    std::size_t at = 1;
    const std::string msg = awaitChild(child, path, progress, expectedBytes, at);
    std::cerr << takeField(msg, at);
    const vtkSmartPointer<vtkDataArray> scalars =
        mappedScalars(child.mem, r->GetDataScalarType(), comps, values);
    auto img = vtkSmartPointer<vtkImageData>::New();
    img->SetExtent(ext);
    img->SetSpacing(r->GetDataSpacing());
    img->SetOrigin(r->GetDataOrigin());
    img->GetPointData()->SetScalars(scalars);
    return img;
}

/// How a reader's data read is run when the caller can cancel (see readContained).
enum class DataRead {
    Abortable,  ///< in process: the reader's progress events abort it
    Contained,  ///< the reader cannot be interrupted: in a child process the parent can kill
};

/// Runs a vtkImageReader2: header, size checks before any allocation, then the data (in a child
/// when `how` says the reader cannot be interrupted and `progress` can cancel; `expectedBytes` as
/// for readContained). The reader opens `readFrom` when given (messages still name `path`).
vtkSmartPointer<vtkImageData> runImageReader(vtkImageReader2* r, const fs::path& path,
                                             const core::Progress& progress,
                                             DataRead how = DataRead::Abortable,
                                             std::uint64_t expectedBytes = 0,
                                             const fs::path& readFrom = {}) {
    r->SetFileName((readFrom.empty() ? path : readFrom).c_str());
    runVtkChecked(r, path, "header", [&] { r->UpdateInformation(); });
    int ext[6];
    r->GetDataExtent(ext);
    checkExtent(ext, r->GetNumberOfScalarComponents(), path);
    if (how == DataRead::Contained && progress.cancellable())
        return readContained(r, path, expectedBytes, progress);
    runVtkChecked(
        r, path, "data", [&] { r->Update(); }, progress);
    return r->GetOutput();
}

/// One file of an Analyze-style pair (analyzePair): the rest of its name and how it was named.
struct AnalyzePair {
    std::string stem;         ///< the path without its extensions
    bool imageNamed = false;  ///< the .img was named (else the .hdr)
    bool upperCase = false;   ///< its extension is upper case (.IMG)
    /// The pair's files that may hold its header or image, the named file's case first (VTK
    /// swaps .img and .hdr keeping the case; the reader is chosen whatever the case).
    std::vector<fs::path> candidates(const char* ext) const {
        std::string upper = ext;
        for (char& c : upper) c = char(std::toupper(static_cast<unsigned char>(c)));
        std::vector<fs::path> out;
        for (const std::string& e : {std::string(ext), upper})
            for (const char* gz : {"", ".gz", ".GZ"}) out.push_back(stem + e + gz);
        if (upperCase) std::swap(out[0], out[3]);
        return out;
    }
};

/// `path` as one file of an Analyze-style pair (.hdr beside .img, either gzipped, any case),
/// read from both files; nothing for a .nii, which holds header and data.
std::optional<AnalyzePair> analyzePair(const fs::path& path) {
    AnalyzePair pair{path.string()};
    const auto strip = [&](const char* ext) {
        const std::string e = ext;
        if (pair.stem.size() <= e.size()) return false;
        const std::string tail = lowerName(pair.stem.substr(pair.stem.size() - e.size()));
        if (tail != e) return false;
        pair.upperCase = pair.stem.substr(pair.stem.size() - e.size()) != e;
        pair.stem.resize(pair.stem.size() - e.size());
        return true;
    };
    (void)strip(".gz");
    if (strip(".img"))
        pair.imageNamed = true;
    else if (!strip(".hdr"))
        return std::nullopt;
    return pair;
}

/// The file of `path`'s pair that is not named must not be a FIFO, socket or device either (VTK's
/// open() of a FIFO blocks where Ctrl-C cannot reach it).
void refuseSpecialCompanion(const fs::path& path) {
    const std::optional<AnalyzePair> pair = analyzePair(path);
    if (!pair) return;
    for (const char* ext : {".hdr", ".img"})
        for (const fs::path& companion : pair->candidates(ext))
            if (core::isSpecialFile(companion))
                throw InputError(
                    path.string(), "data file",
                    "is read with '" + companion.filename().string() +
                        "', a FIFO, socket or device, not a file",
                    "put the header and image files beside each other as regular files");
}

/// NIfTI-1 (and Analyze) / NIfTI-2 header fields voxlight checks before vtkNIFTIImageReader sees
/// the file: VTK 9.1 crashes on a datatype it does not know and takes NaN spacing at face value.
/// Offsets from nifti1.h / nifti2.h.
constexpr std::int32_t kNifti1HeaderSize = 348, kNifti2HeaderSize = 540;
/// descrip: char[80] in both versions, NUL-terminated only when shorter.
constexpr std::ptrdiff_t kNiftiDescripBytes = 80;
/// Datatype codes fromImageData converts: uint8, int16, int32, float32, float64, int8, uint16,
/// uint32, int64, uint64 (NIfTI's DT_* codes) with their bits per voxel.
const std::map<int, int>& niftiDatatypes() {
    static const std::map<int, int> m = {{2, 8},   {4, 16},   {8, 32},   {16, 32},   {64, 64},
                                         {256, 8}, {512, 16}, {768, 32}, {1024, 64}, {1280, 64}};
    return m;
}

void checkNiftiHeader(const fs::path& named) {
    // VTK reads the header of a pair from the .hdr when the .img is named.
    fs::path path = named;
    if (const std::optional<AnalyzePair> pair = analyzePair(named); pair && pair->imageNamed) {
        std::error_code ec;
        for (const fs::path& header : pair->candidates(".hdr"))
            if (fs::exists(header, ec)) {
                path = header;
                break;
            }
    }
    gzFile f = gzopen(path.c_str(), "rb");  // reads plain files too
    if (!f) return;                         // the reader reports the missing file
    unsigned char h[kNifti2HeaderSize] = {};
    const int got = gzread(f, h, sizeof h);
    gzclose(f);
    if (got < 4) return;  // too short for any header: the reader refuses it
    auto i32 = [&](int off, bool swap) {
        std::uint32_t v;
        std::memcpy(&v, h + off, 4);
        if (swap) v = __builtin_bswap32(v);
        return std::int32_t(v);
    };
    const bool v1 = i32(0, false) == kNifti1HeaderSize || i32(0, true) == kNifti1HeaderSize;
    const bool v2 = i32(0, false) == kNifti2HeaderSize || i32(0, true) == kNifti2HeaderSize;
    // VTK reads a header whose sizeof_hdr is neither (it looks at the magic and dim[0]) and takes
    // what follows at face value: zero spacing, garbage sizes.
    if (!v1 && !v2)
        throw InputError(path.string(), "sizeof_hdr",
                         "is " + std::to_string(i32(0, false)) +
                             ", not 348 (NIfTI-1/Analyze) or 540 (NIfTI-2): not a NIfTI header",
                         "the file is damaged or not NIfTI");
    // VTK takes the layout from the magic, not from sizeof_hdr: "n+2"/"ni2" (…"9") and
    // "\r\n\032\n" at byte 4 is NIfTI-2 whatever sizeof_hdr says (fuzz_nifti_gz: sizeof_hdr 348
    // with that magic was read as a NIfTI-2 header and crashed VTK).
    const bool magic2 = got >= 12 && h[4] == 'n' && (h[5] == '+' || h[5] == 'i') && h[6] >= '2' &&
                        h[6] <= '9' && h[7] == 0 && std::memcmp(h + 8, "\r\n\032\n", 4) == 0;
    if (magic2 != v2)
        throw InputError(path.string(), "sizeof_hdr",
                         "is " + std::to_string(v1 ? kNifti1HeaderSize : kNifti2HeaderSize) +
                             (magic2 ? " but the magic at byte 4 says NIfTI-2 (540)"
                                     : " but the NIfTI-2 magic is missing at byte 4"),
                         "the header is damaged; repair it (e.g. with nibabel)");
    const bool swap = i32(0, false) != (v1 ? kNifti1HeaderSize : kNifti2HeaderSize);
    if (got < (v1 ? kNifti1HeaderSize : kNifti2HeaderSize))
        throw InputError(path.string(), "header",
                         "ends before its " + std::to_string(v1 ? 348 : 540) + " bytes",
                         "the file is truncated");
    auto i16 = [&](int off) {
        std::uint16_t v;
        std::memcpy(&v, h + off, 2);
        if (swap) v = __builtin_bswap16(v);
        return int(std::int16_t(v));
    };
    auto f32 = [&](int off) {
        const std::int32_t bits = i32(off, swap);
        float v;
        std::memcpy(&v, &bits, 4);
        return double(v);
    };
    auto f64 = [&](int off) {
        std::uint64_t bits;
        std::memcpy(&bits, h + off, 8);
        if (swap) bits = __builtin_bswap64(bits);
        double v;
        std::memcpy(&v, &bits, 8);
        return v;
    };
    const int datatype = i16(v1 ? 70 : 12), bitpix = i16(v1 ? 72 : 14);
    const auto it = niftiDatatypes().find(datatype);
    if (it == niftiDatatypes().end())
        throw InputError(path.string(), "datatype",
                         "code " + std::to_string(datatype) + " is not a voxel type voxlight reads",
                         "convert to uint8, int16, uint16 or float32");
    if (bitpix != it->second)
        throw InputError(path.string(), "bitpix",
                         std::to_string(bitpix) + " does not match datatype " +
                             std::to_string(datatype) + " (" + std::to_string(it->second) +
                             " bits)",
                         "repair the header");
    // Without an sform, pixdim is the voxel size (and the qform's scale): 0 is no size — VTK
    // reads it as 1 mm without a word (probe). With an sform the matrix gives the size.
    const int sformCode = v1 ? i16(254) : i32(348, swap);
    for (int a = 1; a <= 3; ++a) {
        const double sp = v1 ? f32(76 + 4 * a) : f64(104 + 8 * a);
        if (!std::isfinite(sp))
            throw InputError(path.string(), "pixdim[" + std::to_string(a) + "]",
                             "voxel spacing is NaN or infinite", "repair the header");
        if (sp == 0.0 && sformCode <= 0)
            throw InputError(path.string(), "pixdim[" + std::to_string(a) + "]",
                             "voxel spacing is 0 and no sform gives it",
                             "repair the header (e.g. with nibabel: set the zooms)");
    }
    // dim[0] outside 1..7 is how VTK detects a byte-swapped header: with sizeof_hdr saying
    // otherwise it reads every field swapped and crashes on the result.
    auto i64 = [&](int off) {
        std::uint64_t bits;
        std::memcpy(&bits, h + off, 8);
        if (swap) bits = __builtin_bswap64(bits);
        return std::int64_t(bits);
    };
    auto dim = [&](int a) -> std::int64_t { return v1 ? i16(40 + 2 * a) : i64(16 + 8 * a); };
    const std::int64_t rank = dim(0);
    if (rank < 1 || rank > 7)
        throw InputError(path.string(), "dim[0]",
                         "is " + std::to_string(rank) + ", must be 1..7 (the number of dimensions)",
                         "the header is damaged; repair it (e.g. with nibabel)");
    std::uint64_t voxels = 1;
    for (int a = 1; a <= rank; ++a) {
        const std::int64_t n = dim(a);
        if (n < 1 || n > std::int64_t(core::kMaxVoxels))
            throw InputError(path.string(), "dim[" + std::to_string(a) + "]",
                             "is " + std::to_string(n) + ", must be at least 1",
                             "the header is damaged; repair it (e.g. with nibabel)");
        voxels = std::min<std::uint64_t>(voxels * std::uint64_t(n), std::uint64_t(1) << 62);
    }
    // Single-file NIfTI (magic n+1 / n+2): the data must fit in the file after vox_offset. (A .gz
    // is checked by the reader, which fails on a short stream.)
    const bool single =
        v1 ? std::memcmp(h + 344, "n+1", 4) == 0 : std::memcmp(h + 4, "n+2", 4) == 0;
    const double offset = v1 ? f32(108) : double(i64(168));
    std::error_code ec;
    const std::uintmax_t fileSize = fs::file_size(path, ec);
    // Compressed: deflate cannot expand beyond kMaxDeflateRatio, so a small .nii.gz claiming
    // gigabytes is refused before VTK allocates them (fuzz_nifti_gz: 4.2 GB for a 600-byte file).
    const std::uint64_t claimed = voxels * std::uint64_t(it->second) / 8;
    if (!ec && hasExtension(path, {".gz"}) &&
        claimed > kMaxDeflateRatio * std::uint64_t(fileSize) + kDeflateSlackBytes)
        throw InputError(path.string(), "data",
                         "the header claims " + std::to_string(claimed) +
                             " data bytes but the compressed file of " + std::to_string(fileSize) +
                             " bytes cannot hold more than " +
                             std::to_string(kMaxDeflateRatio * std::uint64_t(fileSize)),
                         "the file is truncated or its dims are damaged");
    if (single && !ec && !hasExtension(path, {".gz"})) {
        const std::uint64_t headerSize = v1 ? kNifti1HeaderSize : kNifti2HeaderSize;
        if (!std::isfinite(offset) || offset < double(headerSize) || offset > double(fileSize))
            throw InputError(path.string(), "vox_offset",
                             "is " + std::to_string(offset) + ", outside the file of " +
                                 std::to_string(fileSize) + " bytes",
                             "the header is damaged; repair it (e.g. with nibabel)");
        const std::uint64_t need = claimed;
        if (std::uint64_t(offset) + need > fileSize)
            throw InputError(path.string(), "data",
                             "the file holds " + std::to_string(fileSize) +
                                 " bytes but the header claims " + std::to_string(need) +
                                 " data bytes from offset " + std::to_string(std::uint64_t(offset)),
                             "the file is truncated or its dims are damaged");
    }
}

/// Relative disagreement between an sform's column length and pixdim above which the sform's
/// scale is taken: float32 headers that agree differ by ~1e-7.
constexpr double kSformScaleTol = 1e-5;

Volume readNifti(const fs::path& path, const ReadOptions&, const core::Progress& progress) {
    refuseSpecialCompanion(path);
    checkNiftiHeader(path);
    vtkNew<vtkNIFTIImageReader> r;
    const vtkSmartPointer<vtkImageData> img = runImageReader(r, path, progress);

    // NIfTI world (RAS) = M · (vtkOrigin + ijk ⊙ spacing); M from sform (preferred, as nibabel) or
    // qform.
    vtkNIFTIImageHeader* h = r->GetNIFTIHeader();
    vtkMatrix4x4* m = nullptr;
    if (h->GetSFormCode() > 0)
        m = r->GetSFormMatrix();
    else if (h->GetQFormCode() > 0)
        m = r->GetQFormMatrix();
    Geometry g;
    double sp[3], org[3];
    img->GetSpacing(sp);
    img->GetOrigin(org);
    g.spacing = glm::abs(glm::dvec3(sp[0], sp[1], sp[2]));
    for (int c = 0; c < 3; ++c)
        if (!std::isfinite(g.spacing[c]) || !(g.spacing[c] > 0.0))
            throw InputError(
                path.string(), "pixdim[" + std::to_string(c + 1) + "]",
                "voxel spacing " + std::to_string(sp[c]) + " is not a positive size in mm",
                "repair the header (e.g. with nibabel)");
    if (m) {
        glm::dmat3 rot;
        glm::dvec3 t;
        for (int c = 0; c < 3; ++c) {
            for (int rr = 0; rr < 3; ++rr) rot[c][rr] = m->GetElement(rr, c);
            t[c] = m->GetElement(c, 3);
        }
        const glm::dmat3 rasToLps(glm::dvec3(-1, 0, 0), glm::dvec3(0, -1, 0), glm::dvec3(0, 0, 1));
        // VTK divides the matrix by pixdim's spacing: an sform whose scale disagrees with
        // pixdim leaves that ratio in the columns. The sform is the truth (nibabel, ITK): the
        // spacing takes the column's length (an identity sform with pixdim 1, 2, 3 was read as
        // 1 × 2 × 3 mm instead of 1 × 1 × 1; probe). A qform's columns are unit.
        glm::dmat3 d = rasToLps * rot;
        for (int c = 0; c < 3; ++c) {
            const double len = glm::length(d[c]);
            if (len > 0) d[c] /= len;
            // (Float rounding of a consistent header leaves |len − 1| ~1e-7: kept as it was.)
            if (std::abs(len - 1.0) > kSformScaleTol && std::isfinite(len)) g.spacing[c] *= len;
            if (sp[c] < 0) d[c] = -d[c];
        }
        for (int c = 0; c < 3; ++c)
            if (!std::isfinite(g.spacing[c]) || !(g.spacing[c] > 0.0))
                throw InputError(
                    path.string(), "sform", "gives voxel column " + std::to_string(c) + " no size",
                    "repair the header's sform (e.g. with nibabel) or set its code to 0");
        const char* field = h->GetSFormCode() > 0 ? "sform" : "qform";
        checkDirection(d, path, field);
        g.direction = d;
        g.origin = rasToLps * (rot * glm::dvec3(org[0], org[1], org[2]) + t);
        if (!std::isfinite(g.origin.x) || !std::isfinite(g.origin.y) || !std::isfinite(g.origin.z))
            throw InputError(path.string(), field, "has a NaN or infinite offset (origin)",
                             "repair the header's " + std::string(field) +
                                 " (e.g. with nibabel) or set its code to 0");
    } else {
        g.origin = glm::dvec3(org[0], org[1], org[2]);
    }
    Volume v = fromImageData(img, path, g);
    // Neither form: NIfTI's "method 1" leaves the orientation unknown (info said "patient LPS"
    // as if the file did). Axes as stored, named so that left and right are checked.
    if (!m)
        v.warnings.push_back(path.filename().string() +
                             " has no sform or qform: its orientation is unknown, read with i, j "
                             "and k toward the patient's left, posterior and superior (check the "
                             "sides against the anatomy, or add an sform, e.g. with nibabel)");
    // VTK reverses the slices of a file whose qfac is −1 (its K = nk − 1 − k, so that the indices
    // are right-handed) and places them correctly above. Undone, so that the grid is the file's:
    // `info` said LAI for an LAS file and (−19, 0, 117) for its origin (−19, 0, 0) (probe), and
    // voxel (i, j, k) was not the (i, j, k) another tool shows.
    if (r->GetQFac() < 0.0 && v.dims().z > 1) {
        Geometry& vg = v.geometry();
        const std::size_t slice =
            std::size_t(vg.dims.x) * std::size_t(vg.dims.y) * core::voxelBytes(v.type());
        auto* bytes = static_cast<std::byte*>(v.data());
        for (int k = 0, l = vg.dims.z - 1; k < l; ++k, --l)
            std::swap_ranges(bytes + std::size_t(k) * slice, bytes + std::size_t(k + 1) * slice,
                             bytes + std::size_t(l) * slice);
        vg.origin += vg.direction[2] * (vg.spacing.z * double(vg.dims.z - 1));
        vg.direction[2] = glm::dvec3(0.0) - vg.direction[2];  // no "-0" in `info`
    }
    const double slope = r->GetRescaleSlope(), inter = r->GetRescaleIntercept();
    if (std::isfinite(slope) && slope != 0.0) {
        v.mapping.slope = slope;
        v.mapping.intercept = std::isfinite(inter) ? inter : 0.0;
    }
    // descrip is 80 bytes of anything: keep printable ASCII, escape the rest (\xNN), so that
    // `info --json` and the stats stay valid UTF-8.
    // VTK keeps all 80 bytes: a descrip without a NUL is not terminated (fuzz_nifti_gz read past
    // it).
    std::string descrip;
    const char* text = h->GetDescrip() ? h->GetDescrip() : "";
    for (const char* c = text; c < text + kNiftiDescripBytes && *c; ++c) {
        const auto b = static_cast<unsigned char>(*c);
        if (b >= 0x20 && b < 0x7f) {
            descrip += char(b);
        } else {
            char esc[5];
            std::snprintf(esc, sizeof esc, "\\x%02x", b);
            descrip += esc;
        }
    }
    v.description = descrip.empty() ? path.filename().string() : descrip;
    return v;
}

/// Spacing (absolute) and origin of a VTK image; direction left as identity for the caller to set.
/// InputError (field `spacingField` / `originField`) on a zero or non-finite spacing or a
/// non-finite origin: VTK takes them at face value (fuzz_vti: Spacing="1 0 1").
Geometry spacingAndOrigin(vtkImageData* img, const fs::path& path, const char* spacingField,
                          const char* originField) {
    Geometry g;
    double sp[3], org[3];
    img->GetSpacing(sp);
    img->GetOrigin(org);
    for (int a = 0; a < 3; ++a) {
        if (!std::isfinite(sp[a]) || sp[a] == 0.0)
            throw InputError(path.string(), spacingField,
                             "voxel spacing " + std::to_string(sp[a]) + " on axis " +
                                 std::to_string(a) + " is not a positive size in mm",
                             "repair the header");
        if (!std::isfinite(org[a]))
            throw InputError(path.string(), originField, "is NaN or infinite", "repair the header");
    }
    g.spacing = glm::abs(glm::dvec3(sp[0], sp[1], sp[2]));
    g.origin = glm::dvec3(org[0], org[1], org[2]);
    return g;
}

template <class VtkReader>
Volume readSimpleVtk(const fs::path& path, const core::Progress& progress, VtkReader* r,
                     DataRead how = DataRead::Abortable, std::uint64_t expectedBytes = 0,
                     const fs::path& readFrom = {}) {
    const vtkSmartPointer<vtkImageData> img =
        runImageReader(r, path, progress, how, expectedBytes, readFrom);
    Geometry g = spacingAndOrigin(img, path, "spacing", "origin");
    Volume v = fromImageData(img, path, g);
    v.description = path.filename().string();
    return v;
}

/// MetaImage header lines read at most: MetaIO headers hold a few dozen keys.
constexpr int kMaxMetaHeaderLines = 256;
/// MetaImage header bytes read at most (the header ends at ElementDataFile; binary data follows).
constexpr std::size_t kMaxMetaHeaderBytes = std::size_t(1) << 20;
/// MetaIO copies header keys (the characters up to '=', ':' or a line break) and string values
/// (Comment, file names, ...) with strcpy into buffers of 255 bytes: a longer one overflows them
/// (glibc's fortify aborts the process; found by fuzz_metaimage). Header lines — and with
/// ElementDataFile = LIST the listed names — this long or longer are refused first.
constexpr std::size_t kMetaIoFieldBytes = 255;

/// MetaImage "Key = Value" header, up to and including ElementDataFile (the last key).
struct MetaHeader {
    std::vector<std::pair<std::string, std::string>> fields;
    std::uint64_t dataOffset = 0;  ///< bytes before LOCAL data (after the ElementDataFile line)
    bool complete = false;         ///< ElementDataFile was found

    std::size_t longestLine = 0;  ///< characters of the longest header line (and LIST names)
    int longestLineNumber = 0;    ///< its line number, 1-based
    int nulLine = 0;              ///< the first such line holding a NUL byte (0: none)
    int lineWithoutKey = 0;       ///< the first non-blank header line without '=' (0: none)
    /// With ElementDataFile = LIST: the non-blank lines after it (trimmed), at most kMaxDim + 1.
    std::vector<std::string> listNames;

    const std::string* find(const std::string& key) const {
        for (const auto& [k, v] : fields)
            if (k == key) return &v;
        return nullptr;
    }
    std::string value(const std::string& key) const {
        const std::string* v = find(key);
        return v ? *v : std::string();
    }
};

MetaHeader readMetaHeader(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    // The header is read whole, up to its cap: a buffer of the file's size when smaller (a 1 MB
    // zero-filled buffer per read was most of the MetaImage fuzz target's time).
    std::error_code sizeEc;
    const std::uintmax_t fileBytes = fs::file_size(path, sizeEc);
    std::string buf(sizeEc ? kMaxMetaHeaderBytes
                           : std::size_t(std::min<std::uintmax_t>(fileBytes, kMaxMetaHeaderBytes)),
                    '\0');
    in.read(buf.data(), std::streamsize(buf.size()));
    buf.resize(std::size_t(in.gcount()));
    MetaHeader h;
    std::size_t pos = 0;
    for (int n = 0; n < kMaxMetaHeaderLines && pos < buf.size(); ++n) {
        const std::size_t nl = buf.find('\n', pos);
        std::string line = buf.substr(pos, (nl == std::string::npos ? buf.size() : nl) - pos);
        pos = nl == std::string::npos ? buf.size() : nl + 1;
        const auto eq = line.find('=');
        if (eq == std::string::npos) {
            // MetaIO takes it for a key and reads on past its line break for the '=': what it
            // then reads as keys and values is not what this parser checked.
            if (line.find_first_not_of(" \t\r") != std::string::npos && h.lineWithoutKey == 0)
                h.lineWithoutKey = n + 1;
            continue;
        }
        std::string k = line.substr(0, eq), val = line.substr(eq + 1);
        auto trim = [](std::string& s) {
            s.erase(0, s.find_first_not_of(" \t\r"));
            s.erase(s.find_last_not_of(" \t\r") + 1);
        };
        trim(k);
        trim(val);
        h.fields.emplace_back(k, val);
        if (k == "ElementDataFile") {  // last header key; binary data may follow
            h.dataOffset = pos;
            h.complete = true;
            break;
        }
    }
    // The longest line MetaIO will copy (kMetaIoFieldBytes): every line before the data, and the
    // listed file names after "ElementDataFile = LIST".
    const bool list = h.complete && h.value("ElementDataFile").rfind("LIST", 0) == 0;
    for (std::size_t at = h.dataOffset;
         list && at < buf.size() && h.listNames.size() <= std::size_t(core::kMaxDim);) {
        const std::size_t nl = std::min(buf.find('\n', at), buf.size());
        std::string name = buf.substr(at, nl - at);
        name.erase(0, name.find_first_not_of(" \t\r"));
        name.erase(name.find_last_not_of(" \t\r") + 1);
        if (!name.empty()) h.listNames.push_back(name);
        at = nl + 1;
    }
    const std::size_t end = h.complete && !list ? std::size_t(h.dataOffset) : buf.size();
    std::size_t length = 0;
    int line = 1;
    for (std::size_t i = 0; i < end; ++i) {
        if (buf[i] == '\0' && h.nulLine == 0) h.nulLine = line;
        if (buf[i] == '\n') {
            ++line, length = 0;
        } else if (buf[i] != '\r' && ++length > h.longestLine) {
            h.longestLine = length;
            h.longestLineNumber = line;
        }
    }
    return h;
}

/// Numbers of a header value; InputError naming the key unless there are exactly `n` finite ones.
std::vector<double> metaNumbers(const MetaHeader& h, const fs::path& path, const std::string& key,
                                std::size_t n) {
    std::istringstream is(h.value(key));
    std::vector<double> out;
    std::string tok;
    while (is >> tok) {
        char* end = nullptr;
        const double x = std::strtod(tok.c_str(), &end);
        if (*end != '\0' || !std::isfinite(x))
            throw InputError(path.string(), key, "holds '" + tok + "', not a finite number",
                             "fix the MetaImage header");
        out.push_back(x);
    }
    if (out.size() != n)
        throw InputError(
            path.string(), key,
            "has " + std::to_string(out.size()) + " values, expected " + std::to_string(n),
            "fix the MetaImage header");
    return out;
}

/// Refuses what MetaIO loops on, divides by zero on or misreads, before it sees the file.
void validateMetaHeader(const MetaHeader& h, const fs::path& path) {
    const auto fail = [&](const std::string& field, const std::string& problem) {
        throw InputError(path.string(), field, problem, "fix the MetaImage header");
    };
    if (h.longestLine >= kMetaIoFieldBytes)
        fail("header", "line " + std::to_string(h.longestLineNumber) + " has " +
                           std::to_string(h.longestLine) +
                           " characters; MetaIO reads header lines of at most " +
                           std::to_string(kMetaIoFieldBytes - 1));
    // MetaIO reads the header as C strings: a NUL ends a value where this parser does not.
    if (h.nulLine > 0) fail("header", "line " + std::to_string(h.nulLine) + " holds a NUL byte");
    if (h.lineWithoutKey > 0)
        fail("header", "line " + std::to_string(h.lineWithoutKey) + " is not 'Key = Value'");
    for (std::size_t i = 0; i < h.fields.size(); ++i)
        for (std::size_t j = 0; j < i; ++j)
            if (h.fields[i].first == h.fields[j].first) fail(h.fields[i].first, "appears twice");
    if (!h.complete)
        fail("ElementDataFile", "is missing (or comes after " +
                                    std::to_string(kMaxMetaHeaderLines) + " header lines)");
    if (!h.find("NDims")) fail("NDims", "is missing");
    const std::string nd = h.value("NDims");
    if (nd != "2" && nd != "3")
        fail("NDims", "is '" + nd + "'; voxlight reads 3-D volumes (or 2-D slices)");
    const std::size_t ndims = std::size_t(nd[0] - '0');
    if (!h.find("DimSize")) fail("DimSize", "is missing");
    for (double d : metaNumbers(h, path, "DimSize", ndims))
        if (d < 1 || d != std::floor(d) || d > core::kMaxDim)
            fail("DimSize", "holds " + std::to_string(d) + "; sizes must be integers 1.." +
                                std::to_string(core::kMaxDim));
    for (const char* key : {"ElementSpacing", "ElementSize"})
        if (h.find(key))
            for (double s : metaNumbers(h, path, key, ndims))
                if (!(s > 0)) fail(key, "holds " + std::to_string(s) + "; must be positive");
    // MetaIO allocates CompressedDataSize bytes as given (a negative one asks for 2^64 − n).
    if (h.find("CompressedDataSize")) {
        // ≤ 2^53 as well: larger values are not exact in a double and overflowed the byte
        // count's conversion (fuzz_metaimage: 1e300, undefined behaviour in UBSan).
        const double c = metaNumbers(h, path, "CompressedDataSize", 1)[0];
        if (!(c >= 1) || c != std::floor(c) || c > 9007199254740992.0)
            fail("CompressedDataSize", "holds " + h.value("CompressedDataSize") +
                                           "; must be a whole number of bytes in 1..2^53");
    }
    for (const char* key : {"Offset", "Position", "Origin"})
        if (h.find(key)) metaNumbers(h, path, key, ndims);
    for (const char* key : {"TransformMatrix", "Rotation", "Orientation"})
        if (h.find(key)) metaNumbers(h, path, key, ndims * ndims);
    // A file pattern "name%03d.raw first last step": step 0 divides by zero inside MetaIO.
    const std::string df = h.value("ElementDataFile");
    if (df.find('%') != std::string::npos) {
        // Exactly "pattern first last step [slice dimension]", integers, as MetaIO splits it
        // (a stray word becomes its file dimension, which it divides by).
        std::istringstream is(df);
        std::vector<std::string> words;
        for (std::string w; is >> w;) words.push_back(w);
        auto integer = [](const std::string& w, long long& out) {
            char* end = nullptr;
            errno = 0;
            out = std::strtoll(w.c_str(), &end, 10);
            return !w.empty() && *end == '\0' && errno == 0;
        };
        // MetaIO hands the pattern to snprintf with one int: exactly one conversion, %d with an
        // optional zero flag and width ("%n", "%s" or a second % would read or write memory).
        auto onePercentD = [](const std::string& f) {
            const std::size_t p = f.find('%');
            if (p == std::string::npos || f.find('%', p + 1) != std::string::npos) return false;
            std::size_t q = p + 1;
            while (q < f.size() && q - p <= 3 && std::isdigit(static_cast<unsigned char>(f[q])))
                ++q;
            return q < f.size() && f[q] == 'd';
        };
        long long first = 0, last = 0, step = 0, dim = 1;
        const bool ok =
            (words.size() == 4 || words.size() == 5) && onePercentD(words[0]) &&
            integer(words[1], first) && integer(words[2], last) && integer(words[3], step) &&
            step != 0 && (last - first) / step >= 0 &&
            (words.size() == 4 || (integer(words[4], dim) && dim >= 1 && dim <= (long long)ndims));
        if (!ok)
            fail("ElementDataFile",
                 "'" + df + "' is not a valid 'pattern first last step [slice dimension]'");
    }
}

/// Redirects std::cerr (where MetaIO reports short or undecompressible data) into a string while
/// alive. std::cerr is process-wide: captures are serialised, and anything another thread writes to
/// std::cerr meanwhile is captured too (voxlight's own progress and messages use stdio's stderr).
class CerrCapture {
  public:
    CerrCapture() : lock_(mutex()), old_(std::cerr.rdbuf(text_.rdbuf())) {}
    ~CerrCapture() { std::cerr.rdbuf(old_); }
    CerrCapture(const CerrCapture&) = delete;
    CerrCapture& operator=(const CerrCapture&) = delete;
    std::string firstLine() const {
        std::string s = text_.str();
        s.erase(0, s.find_first_not_of(" \t\r\n"));
        return s.substr(0, s.find('\n'));
    }

  private:
    static std::mutex& mutex() {
        static std::mutex m;
        return m;
    }
    std::lock_guard<std::mutex> lock_;
    std::ostringstream text_;
    std::streambuf* old_;
};

/// Inflates MetaImage compressed data (zlib format, as MetaIO reads it) into a scratch buffer to
/// prove it yields the `need` bytes MetaIO will ask for: MetaIO's own loop spins forever on some
/// damaged streams (found by fuzz_metaimage_mhd), so a stream that ends early, is corrupt or runs
/// out of input is refused before MetaIO sees it. One extra inflate pass (the data is read again
/// by MetaIO); Ctrl-C is honoured (progress is MetaIO's read's).
void checkMetaDeflate(const fs::path& file, std::uint64_t offset, std::uint64_t bytes,
                      std::uint64_t need, const fs::path& header, const core::Progress& progress) {
    std::ifstream in(file, std::ios::binary);
    in.seekg(std::streamoff(offset));
    z_stream z{};
    if (inflateInit(&z) != Z_OK) throw std::bad_alloc();
    struct End {
        z_stream* z;
        ~End() { inflateEnd(z); }
    } end{&z};
    constexpr std::size_t kChunk = std::size_t(1) << 20;
    // Buffers no larger than the data (two zero-filled 1 MB buffers per small file: 3 % of the
    // MetaImage fuzz target's time).
    std::vector<unsigned char> input(std::size_t(std::min<std::uint64_t>(bytes, kChunk))),
        output(std::size_t(std::min<std::uint64_t>(need, kChunk)));
    std::uint64_t left = bytes, produced = 0;
    auto fail = [&](const std::string& why) {
        throw InputError(file.string(), "data",
                         "compressed data " + why + " (header " + header.filename().string() +
                             " claims " + std::to_string(need) + " voxel bytes)",
                         "the data is truncated or corrupt; copy it again");
    };
    while (produced < need) {
        if (z.avail_in == 0) {
            if (left == 0) fail("ends after " + std::to_string(produced) + " bytes");
            in.read(reinterpret_cast<char*>(input.data()),
                    std::streamsize(std::min<std::uint64_t>(left, input.size())));
            const std::size_t got = std::size_t(in.gcount());
            if (got == 0) fail("ends after " + std::to_string(produced) + " bytes");
            left -= got;
            z.next_in = input.data();
            z.avail_in = uInt(got);
            progress.checkCancel();
        }
        z.next_out = output.data();
        const std::uint64_t ask = std::min<std::uint64_t>(output.size(), need - produced);
        z.avail_out = uInt(ask);
        const uInt inBefore = z.avail_in, outBefore = z.avail_out;
        const int rc = inflate(&z, Z_NO_FLUSH);
        produced += ask - z.avail_out;
        if (rc == Z_BUF_ERROR && z.avail_in == inBefore && z.avail_out == outBefore &&
            z.avail_in > 0)
            fail("makes no progress after " + std::to_string(produced) + " bytes");
        if (rc == Z_STREAM_END && produced < need)
            fail("ends after " + std::to_string(produced) + " bytes");
        if (rc != Z_OK && rc != Z_STREAM_END && rc != Z_BUF_ERROR)
            fail(std::string("cannot be inflated: ") +
                 (z.msg ? z.msg : "zlib error " + std::to_string(rc)));
    }
}

/// MetaIO's scalar element types (those vtkMetaImageReader maps to a VTK type).
bool knownMetaElementType(const std::string& t) {
    static const char* const kTypes[] = {
        "MET_CHAR", "MET_UCHAR", "MET_SHORT",     "MET_USHORT",     "MET_INT",   "MET_UINT",
        "MET_LONG", "MET_ULONG", "MET_LONG_LONG", "MET_ULONG_LONG", "MET_FLOAT", "MET_DOUBLE"};
    return std::any_of(std::begin(kTypes), std::end(kTypes), [&](const char* k) { return t == k; });
}

/// A MetaIO boolean ("True"/"False", any case, or 1/0); InputError naming the key otherwise.
bool metaBool(const MetaHeader& h, const fs::path& path, const std::string& key, bool dflt) {
    if (!h.find(key)) return dflt;
    std::string v = h.value(key);
    std::transform(v.begin(), v.end(), v.begin(), [](unsigned char c) { return std::tolower(c); });
    if (v == "true" || v == "1") return true;
    if (v == "false" || v == "0") return false;
    throw InputError(path.string(), key, "is '" + h.value(key) + "', not True or False",
                     "fix the MetaImage header");
}

/// A MetaScratch directory older than this belongs to a process that was killed (SIGKILL skips
/// the destructor): reading a header takes seconds, so an hour is safe. They hold only a small
/// header and symbolic links, never data, so removing them cannot lose anything.
constexpr std::chrono::hours kStaleScratchAge{1};

/// Removes the stale voxlight-mhd-* directories under `tmp` (errors ignored: another process may
/// remove the same one at the same time).
void removeStaleMetaScratch(const fs::path& tmp) {
    std::error_code ec;
    const auto now = fs::file_time_type::clock::now();
    for (fs::directory_iterator it(tmp, ec), end; !ec && it != end; it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (name.rfind("voxlight-mhd-", 0) != 0 || !it->is_directory(ec) || it->is_symlink(ec))
            continue;
        const auto age = now - fs::last_write_time(it->path(), ec);
        if (!ec && age > kStaleScratchAge) fs::remove_all(it->path(), ec);
        ec.clear();
    }
}

/// The header MetaIO is given instead of the user's (see readMeta), in a private temporary
/// directory with links to the data files under short names; removed when this goes away (and
/// by a later read, once stale, when the process was killed before that).
class MetaScratch {
  public:
    MetaScratch() {
        removeStaleMetaScratch(fs::temp_directory_path());
        std::string dir = (fs::temp_directory_path() / "voxlight-mhd-XXXXXX").string();
        if (!::mkdtemp(dir.data()))
            throw std::runtime_error("cannot create a temporary directory in " +
                                     fs::temp_directory_path().string() + ": " +
                                     std::strerror(errno));
        dir_ = dir;
    }
    ~MetaScratch() {
        std::error_code ec;
        fs::remove_all(dir_, ec);
    }
    MetaScratch(const MetaScratch&) = delete;
    MetaScratch& operator=(const MetaScratch&) = delete;

    /// A short name in the directory that resolves to `target`.
    std::string link(const fs::path& target) {
        const std::string name = "d" + std::to_string(links_++) + ".raw";
        std::error_code ec;
        fs::create_symlink(fs::absolute(target, ec), dir_ / name, ec);
        if (ec)
            throw std::runtime_error("cannot link " + target.string() + " into " + dir_.string() +
                                     ": " + ec.message());
        return name;
    }
    fs::path write(const std::string& header) const {
        const fs::path p = dir_ / "h.mhd";
        std::ofstream out(p, std::ios::binary);
        out << header;
        out.close();
        if (!out) throw std::runtime_error("cannot write " + p.string());
        return p;
    }

  private:
    fs::path dir_;
    int links_ = 0;
};

/// The data files of a validated header, in MetaIO's order (one file; LIST names; a pattern
/// expanded), with how many dimensions each file holds. InputError when the count does not match
/// DimSize or a file cannot be opened.
/// A data file `name` (at `f`) the header `path` names must exist and not be a folder. (A FIFO or
/// device is MetaIO's to read, in the child process Ctrl-C can stop — as a hung network share:
/// test_cli's CtrlCStopsAReadBlockedInsideTheReader.)
void checkMetaDataFile(const fs::path& f, const std::string& name, const fs::path& path) {
    std::error_code ec;
    if (!fs::exists(f, ec) || fs::is_directory(f, ec))
        throw InputError(path.string(), "ElementDataFile",
                         "names '" + name + "', which cannot be opened",
                         "put the data file beside the header");
}

std::vector<fs::path> metaDataFiles(const MetaHeader& h, const fs::path& path, int& fileDims) {
    const std::string df = h.value("ElementDataFile");
    const int ndims = h.value("NDims")[0] - '0';
    const std::vector<double> dims = metaNumbers(h, path, "DimSize", std::size_t(ndims));
    fileDims = ndims;
    if (df == "LOCAL") return {path};
    const bool list = df.rfind("LIST", 0) == 0;
    const bool pattern = df.find('%') != std::string::npos;
    if (!list && !pattern) {
        const fs::path f = path.parent_path() / df;
        checkMetaDataFile(f, df, path);
        return {f};
    }
    std::vector<std::string> names;
    fileDims = ndims - 1;
    if (list) {
        std::istringstream is(df.substr(4));
        std::string w;
        if (is >> w) {  // "LIST 2D": the dimensions of each file
            char* end = nullptr;
            const long d = std::strtol(w.c_str(), &end, 10);
            if ((std::string(end) != "D" && std::string(end) != "") || d < 1 || d > ndims ||
                (is >> w))
                throw InputError(
                    path.string(), "ElementDataFile",
                    "'" + df + "' is not 'LIST' or 'LIST nD' with n in 1.." + std::to_string(ndims),
                    "fix the MetaImage header");
            fileDims = int(d);
        }
        names = h.listNames;
    } else {
        std::istringstream is(df);
        std::string format;
        long long first = 0, last = 0, step = 1, dim = fileDims;
        is >> format >> first >> last >> step;
        if (is >> dim) fileDims = int(dim);  // validateMetaHeader checked every word
        const std::uint64_t count = std::uint64_t((last - first) / step) + 1;
        if (count > std::uint64_t(core::kMaxDim) || std::llabs(first) > INT32_MAX ||
            std::llabs(last) > INT32_MAX)
            throw InputError(path.string(), "ElementDataFile",
                             "'" + df + "' names " + std::to_string(count) + " files",
                             "fix the MetaImage header");
        for (long long i = first; step > 0 ? i <= last : i >= last; i += step) {
            char name[kMetaIoFieldBytes + 16];
            std::snprintf(name, sizeof name, format.c_str(), int(i));  // exactly one %0Nd
            names.emplace_back(name);
        }
    }
    std::uint64_t expected = 1;
    for (int a = fileDims; a < ndims; ++a) expected *= std::uint64_t(dims[std::size_t(a)]);
    if (names.size() != expected)
        throw InputError(path.string(), "ElementDataFile",
                         (list ? "LIST names " : "'" + df + "' names ") +
                             std::to_string(names.size()) + " files; DimSize needs " +
                             std::to_string(expected) + " files of " + std::to_string(fileDims) +
                             " dimensions",
                         "fix the file list or DimSize");
    std::vector<fs::path> files;
    for (const std::string& n : names) {
        const fs::path f = path.parent_path() / n;
        checkMetaDataFile(f, n, path);
        files.push_back(f);
    }
    return files;
}

/// The header MetaIO reads in place of the user's: only the fields voxlight uses, each already
/// validated and written back in one canonical form, with the data files linked under short
/// names. MetaIO's own header parser (fixed-size buffers, unchecked scanf/atoi, format strings
/// built from the file) has yielded one fault after another to fuzzing; it now only ever sees
/// this text. `skip` is where the data starts in a single data file (HeaderSize; -1: MetaIO's
/// "the data ends the file").
std::string canonicalMetaHeader(const MetaHeader& h, const fs::path& path, MetaScratch& scratch,
                                const std::vector<fs::path>& files, int fileDims, long long skip,
                                bool compressed) {
    const int ndims = h.value("NDims")[0] - '0';
    std::ostringstream o;
    o.precision(17);
    auto numbers = [&](const char* key, std::size_t n) {
        for (double x : metaNumbers(h, path, key, n)) o << ' ' << x;
        o << '\n';
    };
    o << "ObjectType = Image\nNDims = " << ndims << "\nDimSize =";
    numbers("DimSize", std::size_t(ndims));
    for (const char* key : {"ElementSpacing", "ElementSize"})
        if (h.find(key)) {
            o << "ElementSpacing =";
            numbers(key, std::size_t(ndims));
            break;
        }
    for (const char* key : {"Offset", "Position", "Origin"})
        if (h.find(key)) {
            o << "Offset =";
            numbers(key, std::size_t(ndims));
            break;
        }
    if (h.find("ElementNumberOfChannels")) {
        const double c = metaNumbers(h, path, "ElementNumberOfChannels", 1)[0];
        if (c < 1 || c > 4 || c != std::floor(c))
            throw InputError(path.string(), "ElementNumberOfChannels",
                             "is " + h.value("ElementNumberOfChannels") + "; voxlight reads 1..4",
                             "fix the MetaImage header");
        o << "ElementNumberOfChannels = " << int(c) << '\n';
    }
    if (!h.find("ElementType"))
        throw InputError(path.string(), "ElementType", "is missing", "fix the MetaImage header");
    if (!knownMetaElementType(h.value("ElementType")))
        throw InputError(path.string(), "ElementType",
                         "is '" + h.value("ElementType") + "', not a MetaImage scalar type",
                         "use MET_UCHAR, MET_SHORT, MET_FLOAT, ... (MET_CHAR..MET_DOUBLE)");
    o << "ElementType = " << h.value("ElementType") << '\n';
    const bool msb = metaBool(h, path, "ElementByteOrderMSB",
                              metaBool(h, path, "BinaryDataByteOrderMSB", false));
    o << "BinaryData = " << (metaBool(h, path, "BinaryData", true) ? "True" : "False") << '\n';
    o << "ElementByteOrderMSB = " << (msb ? "True" : "False") << '\n';
    if (compressed) {
        if (files.size() != 1)
            throw InputError(path.string(), "CompressedData",
                             "is True with " + std::to_string(files.size()) +
                                 " data files; voxlight reads compressed data from one file",
                             "write the volume as one file");
        if (skip < 0)
            throw InputError(path.string(), "HeaderSize",
                             "is -1 (data at the end of the file) with compressed data",
                             "give the compressed data's offset");
        std::error_code ec;
        const std::uint64_t size = fs::file_size(files[0], ec);
        std::uint64_t bytes = size - std::min<std::uint64_t>(size, std::uint64_t(skip));
        if (h.find("CompressedDataSize"))
            bytes = std::uint64_t(metaNumbers(h, path, "CompressedDataSize", 1)[0]);
        o << "CompressedData = True\nCompressedDataSize = " << bytes << '\n';
    }
    if (files.size() == 1 && fileDims == ndims) {
        o << "HeaderSize = " << skip << "\nElementDataFile = " << scratch.link(files[0]) << '\n';
    } else {
        o << "ElementDataFile = LIST " << fileDims << "D\n";
        for (const fs::path& f : files) o << scratch.link(f) << '\n';
    }
    return o.str();
}

Volume readMeta(const fs::path& path, const ReadOptions&, const core::Progress& progress) {
    const MetaHeader h = readMetaHeader(path);
    validateMetaHeader(h, path);
    // MetaIO reads a header we write from the validated fields, never the user's.
    int fileDims = 0;
    const std::vector<fs::path> files = metaDataFiles(h, path, fileDims);
    const bool isCompressed = metaBool(h, path, "CompressedData", false);
    const bool local = h.value("ElementDataFile") == "LOCAL";
    long long skip = local ? (long long)h.dataOffset : 0;
    if (h.find("HeaderSize")) {
        // Bytes to skip before the data in each file, or -1: the data ends the file.
        const double hs = metaNumbers(h, path, "HeaderSize", 1)[0];
        if (hs < -1 || hs != std::floor(hs) || hs > double(std::int64_t(1) << 52))
            throw InputError(path.string(), "HeaderSize",
                             "is " + h.value("HeaderSize") + "; must be -1 or a whole number ≥ 0",
                             "fix the MetaImage header");
        if (hs != 0 && files.size() > 1)
            throw InputError(path.string(), "HeaderSize",
                             "is " + h.value("HeaderSize") +
                                 " with a list of data files; voxlight reads such lists without "
                                 "per-file headers",
                             "strip the slice files' headers or write one data file");
        skip = hs < 0 ? -1 : skip + (long long)hs;
    }
    MetaScratch scratch;
    const fs::path metaHeader =
        scratch.write(canonicalMetaHeader(h, path, scratch, files, fileDims, skip, isCompressed));
    vtkNew<vtkMetaImageReader> r;
    r->SetFileName(metaHeader.c_str());
    {
        CerrCapture quiet;  // MetaIO's header complaints duplicate VTK's error
        runVtkChecked(r, path, "header", [&] { r->UpdateInformation(); });
    }
    int ext[6];
    r->GetDataExtent(ext);
    checkExtent(ext, r->GetNumberOfScalarComponents(), path);
    // MetaIO reports a short data file on std::cerr only, so check the data length ourselves.
    const std::uint64_t need =
        std::uint64_t(ext[1] - ext[0] + 1) * (ext[3] - ext[2] + 1) * (ext[5] - ext[4] + 1) *
        std::uint64_t(vtkDataArray::GetDataTypeSize(r->GetDataScalarType())) *
        std::uint64_t(r->GetNumberOfScalarComponents());
    // What MetaIO will read, for progress: raw data only (MetaIO reads compressed data whole
    // before it inflates it, so the bytes read say nothing about the time left).
    std::uint64_t fileBytes = isCompressed ? 0 : need;
    for (const fs::path& raw : files) {
        std::error_code ec;
        const std::uint64_t size = fs::file_size(raw, ec);
        if (ec) continue;  // not a regular file (a FIFO): MetaIO reports what it cannot read
        // HeaderSize: bytes to skip before the data (-1: the data ends the file).
        const std::uint64_t have =
            size - std::min<std::uint64_t>(size, std::uint64_t(std::max(skip, 0LL)));
        const std::uint64_t needHere = need / files.size();
        if (!isCompressed && have < needHere)
            throw InputError(raw.string(), "data",
                             "file holds " + std::to_string(have) + " bytes, header " +
                                 path.filename().string() + " claims " + std::to_string(needHere),
                             "the data is truncated; copy it again");
        // Compressed data claiming more than deflate can expand to: refused before MetaIO
        // allocates it (fuzz_metaimage in CI: a small .mha declaring gigabytes went over 2 GB).
        if (isCompressed && need > kMaxDeflateRatio * have + kDeflateSlackBytes)
            throw InputError(raw.string(), "data",
                             "header " + path.filename().string() + " claims " +
                                 std::to_string(need) + " voxel bytes but the " +
                                 std::to_string(have) + " compressed bytes cannot hold more than " +
                                 std::to_string(kMaxDeflateRatio * have),
                             "the file is truncated or its DimSize is damaged");
        if (isCompressed && h.find("CompressedDataSize")) {
            const double claimed = metaNumbers(h, path, "CompressedDataSize", 1)[0];
            if (double(have) < claimed)
                throw InputError(raw.string(), "data",
                                 "file holds " + std::to_string(have) +
                                     " compressed bytes, header claims " +
                                     std::to_string(std::uint64_t(claimed)),
                                 "the data is truncated; copy it again");
        }
    }
    if (isCompressed) {
        std::error_code ec;
        const std::uint64_t size = fs::file_size(files[0], ec);
        if (!ec) {
            const std::uint64_t at =
                std::min<std::uint64_t>(size, std::uint64_t(std::max(skip, 0LL)));
            std::uint64_t bytes = size - at;
            if (h.find("CompressedDataSize"))
                bytes = std::min<std::uint64_t>(
                    bytes, std::uint64_t(metaNumbers(h, path, "CompressedDataSize", 1)[0]));
            checkMetaDeflate(files[0], at, bytes, need, path, progress);
        }
    }
    Volume v;
    {
        // MetaIO loads short or undecompressible data with only a line on std::cerr.
        CerrCapture metaio;
        // MetaIO reads every voxel in one call, without progress events: in a child process
        // that Ctrl-C can stop.
        v = readSimpleVtk(path, progress, r.Get(), DataRead::Contained, fileBytes, metaHeader);
        if (!metaio.firstLine().empty())
            throw InputError(path.string(), "data", "could not be read: " + metaio.firstLine(),
                             "the data is truncated or corrupt; copy it again");
    }
    // Orientation as ITK (which writes most MetaImages) reads it: TransformMatrix holds the
    // direction cosines, one row per axis, in LPS; Offset is voxel (0,0,0)'s centre in LPS (VTK
    // reads it as the origin). AnatomicalOrientation only describes that matrix and is ignored, as
    // ITK does. VTK 9.1's reader ignores TransformMatrix, so apply it here.
    std::string tmKey;  // MetaIO accepts Rotation and Orientation as synonyms
    for (const char* key : {"TransformMatrix", "Rotation", "Orientation"})
        if (tmKey.empty() && h.find(key)) tmKey = key;
    if (!tmKey.empty() && h.value("NDims") == "3") {
        const std::vector<double> e = metaNumbers(h, path, tmKey, 9);
        glm::dmat3 d;
        for (int c = 0; c < 3; ++c)
            for (int rr = 0; rr < 3; ++rr)
                d[c][rr] = e[std::size_t(3 * c + rr)];  // MetaIO: row c = axis c's direction
        checkDirection(d, path, tmKey);
        v.geometry().direction = d;
    }
    const std::string modality = h.value("Modality");
    if (modality == "MET_MOD_CT") v.modality = core::Modality::CT;
    if (modality == "MET_MOD_MR") v.modality = core::Modality::MR;
    return v;
}

Volume readNrrd(const fs::path& path, const ReadOptions&, const core::Progress& progress) {
    // VTK's reader crashes, hangs or zero-fills on bad headers and drops the space fields: validate
    // the header and the data length first, and take the geometry from our own parse.
    const detail::NrrdHeader h = detail::parseNrrdHeader(path);
    detail::checkNrrdDataSize(h, path);
    const Geometry g = detail::nrrdGeometry(h, path);
    vtkNew<vtkNrrdReader> r;
    // VTK reads raw data in rows it can abort; gzip data in one gzread and ascii data in one loop,
    // neither of which it can: those in a child process that Ctrl-C can stop.
    std::uint64_t fileBytes = 0;
    for (const fs::path& f : h.dataFiles.empty() ? std::vector<fs::path>{path} : h.dataFiles) {
        std::error_code ec;
        const auto size = fs::file_size(f, ec);
        if (!ec) fileBytes += size;
    }
    const vtkSmartPointer<vtkImageData> img = runImageReader(
        r, path, progress,
        h.encoding == detail::NrrdEncoding::Raw ? DataRead::Abortable : DataRead::Contained,
        fileBytes);
    Volume v = fromImageData(img, path, g);
    VL_CHECK(v.geometry().dims == g.dims);  // our parse and VTK agree on the layout
    v.description = path.filename().string();
    return v;
}

/// Most bytes of a .vti read as XML text before the appended data (inline data beyond this is
/// left to VTK, which bounds it by the extent checked below).
constexpr std::size_t kMaxVtiXmlBytes = std::size_t(64) << 20;
/// Deepest element nesting accepted: a VTK image file has 6 levels; VTK's XML parser recurses per
/// level and overflows the stack on a few hundred thousand.
constexpr int kMaxVtiDepth = 32;

/// Reads the tag starting at `tag` ('<name ...>') as an XML parser does: attributes separated by
/// white space, '=' with optional white space around it, values in "…" or '…' (which may hold
/// '>'). Calls `visit(name, value)` per attribute; returns the position of the tag's closing '>',
/// or npos when the text ends first.
template <class Visit>
std::size_t scanXmlTag(const std::string& xml, std::size_t tag, Visit&& visit) {
    auto space = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; };
    const std::size_t n = xml.size();
    std::size_t i = tag + 1;
    while (i < n && !space(xml[i]) && xml[i] != '>' && xml[i] != '/') ++i;  // the element name
    while (i < n) {
        while (i < n && space(xml[i])) ++i;
        if (i >= n) break;
        if (xml[i] == '>') return i;
        if (xml[i] == '/') {
            ++i;
            continue;
        }
        const std::size_t nameStart = i;
        while (i < n && !space(xml[i]) && xml[i] != '=' && xml[i] != '>' && xml[i] != '/') ++i;
        const std::string name = xml.substr(nameStart, i - nameStart);
        while (i < n && space(xml[i])) ++i;
        if (i >= n || xml[i] != '=') continue;  // malformed: the parser refuses the file
        ++i;
        while (i < n && space(xml[i])) ++i;
        if (i >= n || (xml[i] != '"' && xml[i] != '\'')) continue;
        const std::size_t close = xml.find(xml[i], i + 1);
        if (close == std::string::npos) break;
        visit(name, xml.substr(i + 1, close - i - 1));
        i = close + 1;
    }
    return std::string::npos;
}

/// The value of attribute `name` in the tag starting at `tag`, or nullopt when it has none.
std::optional<std::string> xmlAttribute(const std::string& xml, std::size_t tag,
                                        const std::string& name) {
    std::optional<std::string> found;
    scanXmlTag(xml, tag, [&](const std::string& key, const std::string& value) {
        if (key == name && !found) found = value;
    });
    return found;
}

/// Bytes of `n` words of `wordBytes` at `at` in the appended block (raw or base64), or empty
/// when the file ends first.
std::vector<unsigned char> appendedWords(std::ifstream& in, std::uint64_t at, std::size_t n,
                                         std::size_t wordBytes, bool base64) {
    const std::size_t bytes = n * wordBytes;
    const std::size_t chars = base64 ? (bytes + 2) / 3 * 4 : bytes;
    std::string text(chars, '\0');
    in.clear();
    in.seekg(std::streamoff(at));
    in.read(text.data(), std::streamsize(chars));
    if (std::size_t(in.gcount()) != chars) return {};
    if (!base64) return {text.begin(), text.end()};
    static const std::string kAlphabet =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::vector<unsigned char> out;
    std::uint32_t acc = 0;
    int bits = 0;
    for (char c : text) {
        const std::size_t v = kAlphabet.find(c);
        if (v == std::string::npos) break;  // '=' padding or damage: what was decoded counts
        acc = (acc << 6) | std::uint32_t(v);
        bits += 6;
        if (bits >= 8) {
            bits -= 8;
            out.push_back(static_cast<unsigned char>((acc >> bits) & 0xff));
        }
    }
    if (out.size() < bytes) return {};
    out.resize(bytes);
    return out;
}

/// What vtkXMLImageDataReader would be handed, checked first: element nesting (deep XML crashes
/// its parser) and each binary array's size words — appended or inline — against the extent and
/// against the bytes the file holds (a compressed block relabelled raw, or a compressed header
/// claiming 2³² blocks, makes VTK allocate gigabytes).
void checkVtiFile(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return;  // the reader reports it
    in.seekg(0, std::ios::end);
    const std::uint64_t fileSize = std::uint64_t(in.tellg());
    in.seekg(0);
    std::string xml(std::size_t(std::min<std::uint64_t>(fileSize, kMaxVtiXmlBytes)), '\0');
    in.read(xml.data(), std::streamsize(xml.size()));
    const std::size_t appended = xml.find("<AppendedData");
    if (appended != std::string::npos) xml.resize(appended + 1);
    // Comments and CDATA sections are blanked (same length: positions stay file offsets) before
    // anything is looked for: "<ImageData" or a run of "</" inside a comment made these checks
    // read the wrong element or miscount the nesting, and VTK then crashed.
    for (std::size_t i = xml.find('<'); i != std::string::npos; i = xml.find('<', i + 1)) {
        for (const auto& [open, close] :
             {std::pair<std::string_view, std::string_view>{"<!--", "-->"}, {"<![CDATA[", "]]>"}}) {
            if (xml.compare(i, open.size(), open) != 0) continue;
            const std::size_t end = xml.find(close, i + open.size());
            const std::size_t stop = end == std::string::npos ? xml.size() : end + close.size();
            std::fill(xml.begin() + std::ptrdiff_t(i), xml.begin() + std::ptrdiff_t(stop), ' ');
            i = stop - 1;
            break;
        }
    }
    // Nesting: '<name' opens, '</' closes, '/>' closes what it opened; <? ?> skipped. A tag ends
    // at its first '>' outside quotes ('<a x="/>">' is not self-closing).
    int depth = 0;
    for (std::size_t i = xml.find('<'); i != std::string::npos && i + 1 < xml.size();
         i = xml.find('<', i + 1)) {
        const char next = xml[i + 1];
        if (next == '?' || next == '!') continue;
        if (next == '/') {
            --depth;
            continue;
        }
        const std::size_t close = scanXmlTag(xml, i, [](const auto&, const auto&) {});
        if (close != std::string::npos && close > 0 && xml[close - 1] == '/') continue;
        if (++depth > kMaxVtiDepth)
            throw InputError(path.string(), "XML",
                             "nests elements deeper than " + std::to_string(kMaxVtiDepth) +
                                 " levels (byte " + std::to_string(i) + ")",
                             "the file is damaged or not a VTK image file");
    }
    // An attribute as the XML parser hands it to VTK. A character reference ("&#48;") would be
    // decoded there and not here, so a value holding one is refused rather than misread.
    auto attribute = [&](const std::string& text, std::size_t tag,
                         const char* name) -> std::optional<std::string> {
        std::optional<std::string> v = xmlAttribute(text, tag, name);
        if (v && v->find('&') != std::string::npos)
            throw InputError(
                path.string(), name,
                "holds an XML character or entity reference ('" + v->substr(0, 40) + "')",
                "write the value as plain text");
        return v;
    };
    auto text = [&](const std::string& xmlText, std::size_t tag, const char* name) {
        return attribute(xmlText, tag, name).value_or(std::string());
    };
    // Geometry attributes: VTK replaces one that does not parse (Spacing="1 nan 1") by its
    // default (1 1 1) without a word — a silently wrong geometry.
    if (const std::size_t tag = xml.find("<ImageData"); tag != std::string::npos) {
        for (const auto& [name, count] :
             {std::pair<const char*, int>{"Spacing", 3}, {"Origin", 3}, {"Direction", 9}}) {
            const std::string value = text(xml, tag, name);
            if (value.empty()) continue;  // absent: VTK's default is right
            std::istringstream words(value);
            std::string w;
            int n = 0;
            bool ok = true;
            while (words >> w) {
                char* end = nullptr;
                const double v = std::strtod(w.c_str(), &end);
                ok = ok && end == w.c_str() + w.size() && std::isfinite(v);
                ++n;
            }
            if (!ok || n != count)
                throw InputError(
                    path.string(), name,
                    "'" + value + "' is not " + std::to_string(count) + " finite numbers",
                    "repair the header");
        }
    }
    // Pieces: VTK copies a piece's data into the whole extent by the piece's own extent; one that
    // is inverted (7 0) or reaches outside the whole extent made it copy from a null pointer
    // (fuzzing: SEGV in vtkXMLDataParser::ReadCompressedData).
    if (const std::size_t tag = xml.find("<ImageData"); tag != std::string::npos) {
        std::istringstream whole(text(xml, tag, "WholeExtent"));
        long long w[6];
        bool haveWhole = true;
        for (auto& x : w) haveWhole = haveWhole && bool(whole >> x);
        for (std::size_t piece = xml.find("<Piece", tag); haveWhole && piece != std::string::npos;
             piece = xml.find("<Piece", piece + 1)) {
            const std::string value = text(xml, piece, "Extent");
            std::istringstream words(value);
            long long e[6];
            bool ok = true;
            for (auto& x : e) ok = ok && bool(words >> x);
            for (int a = 0; a < 3 && ok; ++a)
                ok = e[2 * a] <= e[2 * a + 1] && e[2 * a] >= w[2 * a] &&
                     e[2 * a + 1] <= w[2 * a + 1];
            if (!ok)
                throw InputError(path.string(), "Piece Extent",
                                 "'" + value + "' is not 3 ascending ranges inside WholeExtent",
                                 "the file is damaged; re-export the image");
        }
    }
    // Binary arrays: their size words.
    const std::size_t root = xml.find("<VTKFile");
    const std::size_t image = xml.find("<ImageData");
    if (root == std::string::npos || image == std::string::npos) return;  // the reader says so
    const bool compressed = !text(xml, root, "compressor").empty();
    const std::size_t word = text(xml, root, "header_type") == "UInt64" ? 8 : 4;
    const bool bigEndian = text(xml, root, "byte_order") == "BigEndian";
    std::uint64_t voxels = 1;
    {
        std::istringstream ext(text(xml, image, "WholeExtent"));
        long long e[6];
        for (auto& x : e)
            if (!(ext >> x)) return;  // the reader refuses a broken extent
        for (int a = 0; a < 3; ++a) {
            const long long n = e[2 * a + 1] - e[2 * a] + 1;
            if (n < 1 || n > core::kMaxDim) return;  // checkExtent words this one
            voxels *= std::uint64_t(n);
        }
    }
    // The appended block, when there is one: the data starts after '_' (only white space between
    // the tag and it). VTK searches the rest of the file for one and, without it, spent minutes on
    // a 1 KB file.
    bool appendedBase64 = false;
    std::uint64_t dataStart = 0;
    if (appended != std::string::npos) {
        std::ifstream tail(path, std::ios::binary);
        std::string block(4096, '\0');
        tail.seekg(std::streamoff(appended));
        tail.read(block.data(), std::streamsize(block.size()));
        block.resize(std::size_t(tail.gcount()));
        appendedBase64 = text(block, 0, "encoding") != "raw";  // VTK's default is base64
        const std::size_t tagEnd = scanXmlTag(block, 0, [](const auto&, const auto&) {});
        const std::size_t underscore = tagEnd == std::string::npos
                                           ? std::string::npos
                                           : block.find_first_not_of(" \t\r\n", tagEnd + 1);
        if (underscore == std::string::npos || block[underscore] != '_')
            throw InputError(path.string(), "AppendedData",
                             "does not start with the '_' marker before its data",
                             "the file is damaged or not a VTK image file");
        dataStart = appended + underscore + 1;
    }
    auto readWord = [&](const std::vector<unsigned char>& w, std::size_t k) {
        std::uint64_t v = 0;
        for (std::size_t b = 0; b < word; ++b) {
            const std::size_t idx = bigEndian ? k * word + b : k * word + (word - 1 - b);
            v = (v << 8) | w[idx];
        }
        return v;
    };
    static const std::map<std::string, std::uint64_t> kTypeBytes = {
        {"Int8", 1},   {"UInt8", 1}, {"Int16", 2},  {"UInt16", 2},  {"Int32", 4},
        {"UInt32", 4}, {"Int64", 8}, {"UInt64", 8}, {"Float32", 4}, {"Float64", 8}};
    // VTK reads <DataArray> and <Array> elements alike.
    std::vector<std::size_t> arrays;
    for (const std::string_view name : {std::string_view("<DataArray"), std::string_view("<Array")})
        for (std::size_t at = xml.find(name); at != std::string::npos;
             at = xml.find(name, at + 1)) {
            const std::size_t next = at + name.size();
            const char after = next < xml.size() ? xml[next] : '>';
            if (after == ' ' || after == '\t' || after == '\r' || after == '\n' || after == '/' ||
                after == '>')
                arrays.push_back(at);
        }
    std::sort(arrays.begin(), arrays.end());
    for (const std::size_t tag : arrays) {
        // VTK takes an inline array's data to start after the tag's first '>', even one inside a
        // quoted attribute value (Name="s>..." made it read a size word from the name).
        scanXmlTag(xml, tag, [&](const std::string& name, const std::string& value) {
            if (value.find('>') != std::string::npos)
                throw InputError(path.string(), "DataArray " + name,
                                 "holds '>' in its value, where VTK would start the array's data",
                                 "the file is damaged; re-export the image");
        });
        // VTK reads an array with an 'offset' attribute from the appended block whatever its
        // 'format' says (fuzzing: format="appgnded" skipped this check and VTK allocated 17 GB
        // for a compressed header claiming 2³² blocks); without one, format="binary" is inline
        // base64 and anything else ASCII text.
        const std::optional<std::string> offsetText = attribute(xml, tag, "offset");
        const bool inAppended = offsetText.has_value();
        if (!inAppended && text(xml, tag, "format") != "binary") continue;  // ASCII: no sizes
        if (inAppended && appended == std::string::npos) continue;          // the reader says so
        // A type voxlight does not read as voxels (Bit, String, a metadata array) still has its
        // size words checked for structure (a header claiming 2³² blocks), not for an exact size.
        const auto type = kTypeBytes.find(text(xml, tag, "type"));
        const std::uint64_t typeBytes = type == kTypeBytes.end() ? 1 : type->second;
        std::uint64_t offset = 0, comps = 1;
        try {
            if (inAppended) offset = std::stoull(*offsetText);
            if (const std::string c = text(xml, tag, "NumberOfComponents"); !c.empty())
                comps = std::stoull(c);
        } catch (const std::exception&) {
            throw InputError(path.string(), "DataArray",
                             "has a malformed offset or component count", "the file is damaged");
        }
        const std::uint64_t expected = voxels * std::max<std::uint64_t>(comps, 1) * typeBytes;
        // The exact size is known for point data of a piece covering the whole extent (what
        // voxlight and most writers make); cell and field data, and pieces of a split image, get
        // the structural checks only (and the contained read: readVtiInChild).
        const auto lastBefore = [&](const char* name) {
            const std::size_t at = xml.rfind(name, tag);
            return at == std::string::npos ? -1.0 : double(at);
        };
        bool exact =
            type != kTypeBytes.end() &&
            lastBefore("<PointData") > std::max({lastBefore("</PointData"), lastBefore("<CellData"),
                                                 lastBefore("<FieldData")});
        if (exact) {
            const std::size_t piece = xml.rfind("<Piece", tag);
            std::istringstream pe(piece == std::string::npos ? std::string()
                                                             : text(xml, piece, "Extent")),
                whole(text(xml, image, "WholeExtent"));
            long long a = 0, b = 0;
            for (int k = 0; k < 6 && exact; ++k) exact = (pe >> a) && (whole >> b) && a == b;
        }
        auto fail = [&](const std::string& problem) {
            throw InputError(path.string(), inAppended ? "AppendedData" : "DataArray", problem,
                             "the file is damaged, or its compressor or sizes were edited");
        };
        // Where the array's words start and how many bytes it can span: the rest of the file
        // for appended data, the element's text for inline data (always base64).
        std::uint64_t at = 0, remaining = 0;
        bool base64 = true;
        if (inAppended) {
            at = dataStart + offset;
            if (offset >= fileSize || at >= fileSize)
                fail("array offset " + std::to_string(offset) + " is past the file's end");
            remaining = fileSize - at;
            base64 = appendedBase64;
        } else {
            const std::size_t tagEnd = scanXmlTag(xml, tag, [](const auto&, const auto&) {});
            if (tagEnd == std::string::npos || xml[tagEnd - 1] == '/') continue;  // no data
            at = xml.find_first_not_of(" \t\r\n", tagEnd + 1);
            if (at == std::string::npos) continue;  // the reader says so
            const std::size_t end = xml.find('<', at);
            remaining = (end == std::string::npos ? fileSize : end) - at;
        }
        if (!compressed) {
            const auto w = appendedWords(in, at, 1, word, base64);
            if (w.empty()) fail("ends inside an array's size word");
            if (!inAppended) continue;  // VTK reads inline data into the extent's array
            const std::uint64_t n = readWord(w, 0);
            if (exact && n != expected)
                fail("array claims " + std::to_string(n) + " bytes; the extent needs " +
                     std::to_string(expected));
            if ((base64 ? n / 3 * 4 : n) > remaining)
                fail("array of " + std::to_string(n) + " bytes runs past the file's end");
        } else {
            const auto w3 = appendedWords(in, at, 3, word, base64);
            if (w3.empty()) fail("ends inside a compressed array's header");
            const std::uint64_t blocks = readWord(w3, 0), blockSize = readWord(w3, 1),
                                last = readWord(w3, 2);
            if (blocks == 0 || blockSize == 0 || blocks > remaining / word)
                fail("compressed array header claims " + std::to_string(blocks) + " blocks");
            // VTK finds a byte's block by dividing by the block size: a last block larger than
            // the others sends it past the header's block list (it read sizes from the heap and
            // allocated terabytes).
            if (last > blockSize)
                fail("compressed array's last block of " + std::to_string(last) +
                     " bytes is larger than its block size " + std::to_string(blockSize));
            const std::uint64_t total = (blocks - 1) * blockSize + (last ? last : blockSize);
            if (exact && total != expected)
                fail("compressed array holds " + std::to_string(total) +
                     " bytes; the extent needs " + std::to_string(expected));
            const auto all = appendedWords(in, at, std::size_t(3 + blocks), word, base64);
            if (all.empty()) fail("ends inside a compressed array's block sizes");
            std::uint64_t sum = 0;
            for (std::size_t k = 3; k < 3 + blocks; ++k) sum += readWord(all, k);
            if ((base64 ? sum / 3 * 4 : sum) > remaining)
                fail("compressed blocks of " + std::to_string(sum) +
                     " bytes run past the file's end");
        }
    }
}

/// Address space a .vti reading child may use beyond what it had at fork, before the extent is
/// known (VTK's XML parser keeps element text positions, not data) and on top of
/// kVtiChildBytesPerValue per value of the extent after: the parse, the compressed blocks and the
/// decoded array. A header claiming 2³² compressed blocks (17 GB of block sizes) fails there
/// with bad_alloc instead of taking the machine's memory.
constexpr std::size_t kVtiChildHeadroomBytes = std::size_t(512) << 20;
/// Per value of the extent (at most 8 bytes each, several components at most 4×): the decoded
/// array and VTK's copy of it.
constexpr std::size_t kVtiChildBytesPerValue = 64;

/// The .vti child: VTK's XML reader — header and data — runs here, so that what the checks of
/// checkVtiFile do not catch (VTK's parser recursing on deep XML, a size word read from a place
/// the checks did not look) ends this process, not voxlight. Sends 'V' + the image's extent,
/// spacing, origin, direction, scalar type, components and tuples (its voxels in `memFd`), or
/// 'E' (InputError), 'M' (out of memory), 'X' (another exception); then what was printed.
[[noreturn]] void readVtiInChild(const fs::path& path, std::uint64_t fileBytes, int msgFd,
                                 int memFd) {
    becomeReaderChild();
    limitChildMemory(kVtiChildHeadroomBytes);
    std::ostringstream printed;
    std::cerr.rdbuf(printed.rdbuf());
    std::string msg;
    try {
        // Test seam (tests/io/test_bad_input.cpp): the containment itself, apart from the checks
        // that keep the known damaged files away from VTK.
        if (const char* fault = std::getenv("VOXLIGHT_VTI_CHILD_FAULT")) {
            if (std::string_view(fault) == "segv") ::raise(SIGSEGV);
            injectAllocationFault(fault);
        }
        vtkNew<vtkXMLImageDataReader> r;
        r->SetFileName(path.c_str());
        runVtkChecked(r, path, "header", [&] { r->UpdateInformation(); });
        int ext[6];
        r->GetOutputInformation(0)->Get(vtkStreamingDemandDrivenPipeline::WHOLE_EXTENT(), ext);
        checkExtent(ext, 1, path);
        const std::size_t voxels = std::size_t(ext[1] - ext[0] + 1) *
                                   std::size_t(ext[3] - ext[2] + 1) *
                                   std::size_t(ext[5] - ext[4] + 1);
        // A voxel takes at least a byte, or 1/kMaxDeflateRatio of one compressed: an extent the
        // file cannot hold is refused before VTK allocates it (a 500-byte file claimed 1024³).
        if (fileBytes > 0 && voxels > fileBytes * kMaxDeflateRatio + kDeflateSlackBytes)
            throw InputError(path.string(), "WholeExtent",
                             "claims " + std::to_string(voxels) + " voxels; a file of " +
                                 std::to_string(fileBytes) + " bytes holds at most " +
                                 std::to_string(fileBytes * kMaxDeflateRatio + kDeflateSlackBytes) +
                                 " even deflate-compressed",
                             "the file is damaged or truncated");
        limitChildMemory(kVtiChildHeadroomBytes + kVtiChildBytesPerValue * voxels);
        runVtkChecked(r, path, "data", [&] { r->Update(); });
        vtkImageData* img = r->GetOutput();
        vtkDataArray* scalars = imageScalars(img, path);
        const std::size_t values = std::size_t(scalars->GetNumberOfValues());
        const std::size_t bytes = values * std::size_t(scalars->GetDataTypeSize());
        copyIntoMemfd(memFd, scalars->GetVoidPointer(0), bytes);
        img->GetExtent(ext);
        msg = "V";
        auto put = [&](const void* data, std::size_t n) {
            putField(msg, std::string(static_cast<const char*>(data), n));
        };
        put(ext, sizeof ext);
        put(img->GetSpacing(), 3 * sizeof(double));
        put(img->GetOrigin(), 3 * sizeof(double));
        put(img->GetDirectionMatrix()->GetData(), 9 * sizeof(double));
        const std::int64_t shape[3] = {scalars->GetDataType(), scalars->GetNumberOfComponents(),
                                       std::int64_t(values)};
        put(shape, sizeof shape);
    } catch (const InputError& e) {
        msg = "E";
        for (const std::string* f : {&e.source(), &e.field(), &e.problem(), &e.fix()})
            putField(msg, *f);
    } catch (const std::bad_alloc&) {
        msg = "M";
        putField(msg,
                 "over " + std::to_string(kVtiChildHeadroomBytes >> 20) + " MB beyond its voxels");
    } catch (const std::exception& e) {
        msg = "X";
        putField(msg, e.what());
    }
    putField(msg, printed.str());
    sendAll(msgFd, msg);
    ::_exit(0);
}

/// vtkXMLImageDataReader's output, read in a child (readVtiInChild): the image with its scalars
/// mapped from the child's memfd. Progress follows the bytes the child has read of the file.
vtkSmartPointer<vtkImageData> readVtiContained(const fs::path& path, std::uint64_t fileBytes,
                                               const core::Progress& progress) {
    ChildProcess child;
    forkReader(child, path, [&](int msgFd) { readVtiInChild(path, fileBytes, msgFd, child.mem); });
    std::size_t at = 1;
    const std::string msg = awaitChild(child, path, progress, fileBytes, at);
    auto take = [&](void* out, std::size_t n) {
        const std::string f = takeField(msg, at);
        if (f.size() != n) throw InternalError("volume reader: a short message from the child");
        std::memcpy(out, f.data(), n);
    };
    int ext[6];
    double spacing[3], origin[3], direction[9];
    std::int64_t shape[3];
    take(ext, sizeof ext);
    take(spacing, sizeof spacing);
    take(origin, sizeof origin);
    take(direction, sizeof direction);
    take(shape, sizeof shape);
    std::cerr << takeField(msg, at);
    const int comps = int(shape[1]);
    const std::size_t values = std::size_t(shape[2]);
    const vtkSmartPointer<vtkDataArray> scalars =
        mappedScalars(child.mem, int(shape[0]), comps, comps > 0 ? values : 0);
    auto img = vtkSmartPointer<vtkImageData>::New();
    img->SetExtent(ext);
    img->SetSpacing(spacing);
    img->SetOrigin(origin);
    img->SetDirectionMatrix(direction);
    img->GetPointData()->SetScalars(scalars);
    return img;
}

Volume readVti(const fs::path& path, const ReadOptions&, const core::Progress& progress) {
    checkVtiFile(path);
    std::error_code ec;
    const std::uint64_t fileBytes = fs::file_size(path, ec);
    const vtkSmartPointer<vtkImageData> img = readVtiContained(path, ec ? 0 : fileBytes, progress);
    Geometry g = spacingAndOrigin(img, path, "Spacing", "Origin");
    const double* d = img->GetDirectionMatrix()->GetData();  // row-major
    for (int c = 0; c < 3; ++c)
        for (int rr = 0; rr < 3; ++rr) g.direction[c][rr] = d[3 * rr + c];
    checkDirection(g.direction, path, "Direction");
    Volume v = fromImageData(img, path, g);
    v.description = path.filename().string();
    return v;
}

Volume readRaw(const fs::path& path, const RawLayout& layout) {
    for (int a = 0; a < 3; ++a)
        if (layout.dims[a] < 1 || layout.dims[a] > core::kMaxDim)
            throw InputError(path.string(), "dims",
                             std::to_string(layout.dims.x) + "," + std::to_string(layout.dims.y) +
                                 "," + std::to_string(layout.dims.z) + " is not 1.." +
                                 std::to_string(core::kMaxDim) + " voxels per axis",
                             "pass --dims X,Y,Z");
    Geometry g;
    g.dims = layout.dims;
    g.spacing = layout.spacing;
    const int ext[6] = {0, layout.dims.x - 1, 0, layout.dims.y - 1, 0, layout.dims.z - 1};
    checkExtent(ext, 1, path);
    for (int a = 0; a < 3; ++a)
        if (!(layout.spacing[a] >= core::kMinSpacingMm &&
              layout.spacing[a] <= core::kMaxSpacingMm)) {
            // core::Volume's own check would ask to repair a header a raw file does not have.
            std::ostringstream os;
            os << "must be between " << core::kMinSpacingMm << " and " << core::kMaxSpacingMm
               << " mm on every axis";
            throw InputError(path.string(), "--spacing", os.str(), "pass --spacing X,Y,Z in mm");
        }
    const std::uint64_t need = g.voxelCount() * core::voxelBytes(layout.type);
    std::error_code ec;
    const auto have = fs::file_size(path, ec);
    if (ec) throw InputError(path.string(), "file", "cannot be opened", "check the path");
    if (layout.headerBytes > have)  // (before the sum below, which a huge value overflows)
        throw InputError(path.string(), "--header-bytes",
                         std::to_string(layout.headerBytes) + " is past the end of the file (" +
                             std::to_string(have) + " bytes)",
                         "give the size of the file's header in bytes");
    if (have - layout.headerBytes < need)
        throw InputError(path.string(), "data",
                         "is " + std::to_string(have) + " bytes but " +
                             std::to_string(layout.headerBytes) + " header bytes + " +
                             std::to_string(need) + " data bytes are needed for the stated layout",
                         "check --dims, --type and --header-bytes");
    Volume v(g, layout.type);
    std::ifstream in(path, std::ios::binary);
    in.seekg(std::streamoff(layout.headerBytes));
    in.read(static_cast<char*>(v.data()), std::streamsize(need));
    if (!in)
        throw InputError(path.string(), "data", "could not be read completely", "check the file");
    const std::size_t bytes = core::voxelBytes(layout.type);
    const bool hostBig = std::endian::native == std::endian::big;
    if (bytes > 1 && layout.bigEndian != hostBig) {
        auto* p = static_cast<unsigned char*>(v.data());
        for (std::size_t i = 0; i < std::size_t(g.voxelCount()); ++i)
            std::reverse(p + i * bytes, p + (i + 1) * bytes);
    }
    v.description = path.filename().string();
    // Read, but said: a file longer than its layout usually means wrong --dims or --type (or a
    // header, or a compressed file read as raw).
    if (const std::uint64_t extra = have - layout.headerBytes - need; extra > 0)
        v.warnings.push_back(path.filename().string() + " holds " + std::to_string(extra) +
                             " bytes more than --header-bytes + the --dims/--type layout (" +
                             std::to_string(layout.headerBytes + need) +
                             "); they were not read: check --dims and --type");
    return v;
}

/// The "is this my format?" check of a VTK reader class.
template <class VtkReader>
bool vtkCanRead(const fs::path& p) {
    vtkNew<VtkReader> r;
    return r->CanReadFile(p.c_str()) > 0;
}

/// The first bytes of a file (at most `n`).
std::string fileStart(const fs::path& p, std::size_t n) {
    std::ifstream in(p, std::ios::binary);
    std::string s(n, '\0');
    in.read(s.data(), std::streamsize(n));
    s.resize(std::size_t(in.gcount()));
    return s;
}

/// vtkNrrdReader::CanReadFile reads the whole first line (unbounded); its test is the magic "NRRD".
bool nrrdCanRead(const fs::path& p) { return fileStart(p, 4) == "NRRD"; }

/// vtkMetaImageReader::CanReadFile reads the first word into a char[8000] (a longer one overflows
/// it): refuse such files before asking VTK.
bool metaCanRead(const fs::path& p) {
    constexpr std::size_t kVtkMetaKeyBuffer = 8000;
    const std::string head = fileStart(p, 2 * kVtkMetaKeyBuffer);
    const auto begin = head.find_first_not_of(" \t\r\n\v\f");
    if (begin == std::string::npos || begin >= kVtkMetaKeyBuffer) return false;
    const auto end = std::min(head.find_first_of(" \t\r\n\v\f", begin), head.size());
    if (end - begin >= kVtkMetaKeyBuffer) return false;
    return vtkCanRead<vtkMetaImageReader>(p);
}

const std::vector<Reader>& registry() {
    static const std::vector<Reader> readers = {
        {"NIfTI",
         {".nii", ".nii.gz", ".hdr", ".img", ".img.gz"},
         vtkCanRead<vtkNIFTIImageReader>,
         readNifti},
        {"NRRD", {".nrrd", ".nhdr"}, nrrdCanRead, readNrrd},
        {"MetaImage", {".mhd", ".mha"}, metaCanRead, readMeta},
        {"VTK XML image", {".vti"}, vtkCanRead<vtkXMLImageDataReader>, readVti},
        {"DICOM series",
         {".dcm", ".ima", ""},
         [](const fs::path& p) { return detail::looksLikeDicom(p); },
         [](const fs::path& p, const ReadOptions& o, const core::Progress& pr) {
             return detail::readDicomSeries(p, o, pr);
         }},
    };
    return readers;
}

void applyNonFinitePolicy(Volume& v, const fs::path& path, NonFinitePolicy policy) {
    const std::uint64_t bad = v.countNonFinite();
    if (bad == 0) return;
    if (bad == v.voxelCount())
        throw InputError(path.string(), "voxels",
                         "all " + std::to_string(bad) +
                             " voxels are NaN, infinite or beyond float's range: no finite value "
                             "to show or to replace them with",
                         "check the file's data type and byte order");
    if (policy == NonFinitePolicy::Reject)
        throw InputError(path.string(), "voxels",
                         std::to_string(bad) + " of " + std::to_string(v.voxelCount()) +
                             " voxels are NaN, infinite or beyond float's range (±3.4e38)",
                         "replace them by the lowest finite value with --set volume.nonfinite=min "
                         "(\"nonfinite\": \"min\" in the scene's volume; `info` takes "
                         "--nonfinite=min), or rescale data that overflows float");
    const float lo = float((v.mapping.slope >= 0 ? v.physicalRange()[0] : v.physicalRange()[1]) -
                           v.mapping.intercept) /
                     float(v.mapping.slope);
    float* p = v.dataAs<float>();
    for (std::size_t i = 0; i < std::size_t(v.voxelCount()); ++i)
        if (!std::isfinite(p[i])) p[i] = lo;
}

}  // namespace

std::vector<std::string> detail::supportedVolumeFormatsWithVtk() {
    std::vector<std::string> out;
    for (const auto& r : registry()) {
        std::string s = r.name + " (";
        bool first = true;
        for (const auto& e : r.extensions) {
            if (e.empty()) continue;
            s += (first ? "" : ", ") + e;
            first = false;
        }
        if (r.name == "DICOM series") s += ", or a directory";
        out.push_back(s + ")");
    }
    out.push_back("raw (any file, with --dims/--type/--spacing)");
    return out;
}

Volume detail::readVolumeWithVtk(const fs::path& path, const ReadOptions& options,
                                 const core::Progress& progress) {
    std::error_code ec;
    if (!fs::exists(path, ec))
        throw InputError(path.string(), "path", "does not exist",
                         "check the path (relative to the current directory)");
    core::refuseSpecialFile(path);
    // A series UID picks a series of a DICOM folder; on any other file it chose nothing, silently.
    const auto refuseSeries = [&](const std::string& format) {
        if (!options.dicomSeriesUid.empty())
            throw InputError(path.string(), "series",
                             "a DICOM series UID ('" + options.dicomSeriesUid +
                                 "') was given for a " + format + " file",
                             "remove --series (scene: volume.series): it picks one series of a "
                             "DICOM folder");
    };
    Volume v;
    if (options.raw) {
        refuseSeries("raw");
        if (fs::is_directory(path))
            throw InputError(path.string(), "path", "is a directory, not a raw file");
        v = readRaw(path, *options.raw);
        v.format = "raw";
    } else if (fs::is_directory(path)) {
        if (!detail::looksLikeDicom(path))
            throw InputError(path.string(), "path", "is a directory without DICOM files",
                             "pass a volume file, or a folder holding one DICOM series");
        v = detail::readDicomSeries(path, options, progress);
        v.format = "DICOM series";
    } else {
        // Readers whose extension matches first, then content sniffing (DICOM files often have no
        // extension).
        std::vector<const Reader*> order;
        for (const auto& r : registry())
            if (hasExtension(path, r.extensions)) order.push_back(&r);
        for (const auto& r : registry())
            if (std::find(order.begin(), order.end(), &r) == order.end()) order.push_back(&r);
        std::string tried;
        const Reader* chosen = nullptr;
        for (const Reader* r : order) {
            captureWindow().take();
            const bool ok = r->canRead(path);
            captureWindow().take();
            if (ok) {
                chosen = r;
                break;
            }
            tried += (tried.empty() ? "" : ", ") + r->name;
        }
        if (!chosen)
            throw InputError(
                path.string(), "format", "is not a volume voxlight can read (tried " + tried + ")",
                "use NIfTI, NRRD, MetaImage, VTI, a DICOM folder, or raw with --dims/--type");
        if (chosen->name != "DICOM series") refuseSeries(chosen->name);
        v = chosen->read(path, options, progress);
        v.format = chosen->name;
    }
    applyNonFinitePolicy(v, path, options.nonFinite);
    v.geometry().validate();
    // Text from the file (a DICOM SeriesDescription in Latin-1, binary garbage) is printed by
    // `info --json` and written into the stats: one line of valid UTF-8 (fuzz_dicom).
    v.description = oneLine(v.description);
    return v;
}

// ---------------------------------------------------------------------------------------------------------------
// Writing.

namespace {
int vtkTypeOf(VoxelType t) {
    switch (t) {
        case VoxelType::UInt8:
            return VTK_UNSIGNED_CHAR;
        case VoxelType::Int16:
            return VTK_SHORT;
        case VoxelType::UInt16:
            return VTK_UNSIGNED_SHORT;
        case VoxelType::Float32:
            return VTK_FLOAT;
    }
    return VTK_FLOAT;
}

vtkSmartPointer<vtkImageData> toImageData(const Volume& v) {
    auto img = vtkSmartPointer<vtkImageData>::New();
    const Geometry& g = v.geometry();
    img->SetDimensions(g.dims.x, g.dims.y, g.dims.z);
    img->SetSpacing(g.spacing.x, g.spacing.y, g.spacing.z);
    img->SetOrigin(g.origin.x, g.origin.y, g.origin.z);
    double d[9];
    for (int rr = 0; rr < 3; ++rr)
        for (int c = 0; c < 3; ++c) d[3 * rr + c] = g.direction[c][rr];
    img->SetDirectionMatrix(d);
    vtkSmartPointer<vtkDataArray> arr;
    arr.TakeReference(vtkDataArray::CreateDataArray(vtkTypeOf(v.type())));
    arr->SetNumberOfComponents(1);
    // Zero-copy: VTK reads our buffer (save=1: VTK must not free it).
    arr->SetVoidArray(const_cast<void*>(v.data()), vtkIdType(v.voxelCount()), 1);
    arr->SetName("scalars");
    img->GetPointData()->SetScalars(arr);
    return img;
}

bool isIdentity(const glm::dmat3& d) {
    for (int c = 0; c < 3; ++c)
        for (int r = 0; r < 3; ++r)
            if (std::abs(d[c][r] - (r == c ? 1.0 : 0.0)) > 1e-9) return false;
    return true;
}
}  // namespace

namespace {
/// The output format's extension (".nii.gz", ".nii", ".vti", ".mha"), or an InputError.
std::string outputExtension(const fs::path& path) {
    const std::string name = lowerName(path);
    for (const char* e : {".nii.gz", ".nii", ".vti", ".mha"}) {
        const std::string ext = e;
        if (name.size() > ext.size() &&
            name.compare(name.size() - ext.size(), ext.size(), ext) == 0)
            return ext;
    }
    throw InputError(path.string(), "extension", "is not a volume format voxlight writes",
                     "use .nii.gz, .nii, .vti or .mha");
}
fs::path outputDirectory(const fs::path& path) {
    const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
    std::error_code ec;  // a path past PATH_MAX is an error code here, not an exception
    if (!fs::is_directory(dir, ec))
        throw InputError(
            path.string(), "path",
            ec ? "its directory cannot be used: " + ec.message() : "its directory does not exist",
            ec ? "give a shorter path" : "create the directory first");
    return dir;
}
}  // namespace

void detail::checkVolumeOutputPathWithVtk(const fs::path& path) {
    outputExtension(path);
    outputDirectory(path);
}

void detail::writeVolumeWithVtk(const Volume& v, const fs::path& path) {
    const std::string ext = outputExtension(path);
    const fs::path dir = outputDirectory(path);
    // Same directory (same file system) so the final rename is atomic; keep the extension for VTK's
    // writer choice.
    const fs::path tmp =
        dir / (".voxlight-tmp-" + std::to_string(::getpid()) + "-" + path.filename().string());
    vtkSmartPointer<vtkImageData> img = toImageData(v);
    vtkSmartPointer<vtkImageWriter> dummy;
    captureWindow().take();
    auto fail = [&](const std::string& why) {
        // A full disk is the reason whatever VTK said (its XML writer dumps its pipeline state).
        const bool full = core::fileSystemFull(dir);
        std::error_code ec;
        fs::remove(tmp, ec);  // frees the space: asked before
        if (full) throw core::noSpaceLeft(path.string());
        throw InputError(path.string(), "write", why, "check free disk space and permissions");
    };
    if (ext == ".nii" || ext == ".nii.gz") {
        vtkNew<vtkNIFTIImageWriter> w;
        w->SetInputData(img);
        w->SetFileName(tmp.c_str());
        // LPS → RAS for NIfTI's sform/qform; VTK writes the matrix as given, origin folded in
        // below.
        vtkNew<vtkMatrix4x4> m;
        const glm::dmat3 lpsToRas(glm::dvec3(-1, 0, 0), glm::dvec3(0, -1, 0), glm::dvec3(0, 0, 1));
        const glm::dmat3 d = lpsToRas * v.geometry().direction;
        const glm::dvec3 o = lpsToRas * v.geometry().origin;
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) m->SetElement(r, c, d[c][r]);
            m->SetElement(r, 3, o[r]);
        }
        img->SetOrigin(0, 0, 0);
        img->SetDirectionMatrix(1, 0, 0, 0, 1, 0, 0, 0, 1);
        w->SetQFormMatrix(m);
        w->SetSFormMatrix(m);
        w->SetRescaleSlope(v.mapping.slope);
        w->SetRescaleIntercept(v.mapping.intercept);
        w->SetDescription(v.description.substr(0, 79).c_str());
        w->Write();
        if (w->GetErrorCode() != 0) fail("VTK NIfTI writer failed");
    } else if (ext == ".vti") {
        if (v.mapping.slope != 1.0 || v.mapping.intercept != 0.0)
            throw InputError(path.string(), "extension",
                             ".vti cannot store a rescale slope/intercept",
                             "write .nii.gz instead");
        vtkNew<vtkXMLImageDataWriter> w;
        w->SetInputData(img);
        w->SetFileName(tmp.c_str());
        w->SetDataModeToAppended();
        w->SetCompressorTypeToZLib();
        if (w->Write() != 1) fail("VTK XML writer failed");
    } else {
        if (!isIdentity(v.geometry().direction) || v.mapping.slope != 1.0 ||
            v.mapping.intercept != 0.0)
            throw InputError(path.string(), "extension",
                             ".mha output keeps neither orientation nor rescale in VTK 9.1",
                             "write .nii.gz instead");
        vtkNew<vtkMetaImageWriter> w;
        w->SetInputData(img);
        w->SetFileName(tmp.c_str());
        w->SetCompression(true);
        // MetaIO reports a failed write only on std::cerr ("file stream is fail after write"),
        // with GetErrorCode() 0: what it prints there is the failure, said in our one line.
        std::ostringstream metaIo;
        {
            struct CerrTo {
                std::streambuf* saved;
                explicit CerrTo(std::streambuf* b) : saved(std::cerr.rdbuf(b)) {}
                ~CerrTo() { std::cerr.rdbuf(saved); }
            } hold(metaIo.rdbuf());
            w->Write();
        }
        if (w->GetErrorCode() != 0) fail("VTK MetaImage writer failed");
        if (std::string said = metaIo.str(); !said.empty())
            fail("MetaIO: " + said.substr(0, said.find('\n')));
    }
    for (auto& m : captureWindow().take())
        if (m.find("ERROR") != std::string::npos) fail(cleanVtkMessage(m));
    // A writer that reported success over a short file (none known here since MetaIO's line is
    // read above; kept for the others).
    if (core::fileSystemFull(dir)) fail("the disk is full");
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) fail("rename from temporary file failed: " + ec.message());
}

}  // namespace voxlight::io

namespace {
constexpr voxlight::io::volume_module::Api kApi{
    voxlight::io::volume_module::kAbiVersion,
    &voxlight::io::detail::readVolumeWithVtk,
    &voxlight::io::detail::writeVolumeWithVtk,
    &voxlight::io::detail::checkVolumeOutputPathWithVtk,
    &voxlight::io::detail::supportedVolumeFormatsWithVtk,
    &voxlight::io::detail::useLoadCounter};
}  // namespace

// The module's single exported symbol (it is built with hidden visibility; volume_module.h).
extern "C" __attribute__((visibility("default"))) const void* voxlight_volume_module() {
    return &kApi;
}
