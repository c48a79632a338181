// SPDX-License-Identifier: MIT
// readDicomSeries in io: loads the GDCM module on first use (dicom_series.h says why GDCM is not
// linked into io) and runs it in a child process.
//
// Why a child: Debian's GDCM is built with assertions on and aborts the process on damaged data
// elements, segfaults in its RAW codec on some short pixel data, and OpenJPEG allocates gigabytes
// on a damaged JPEG 2000 stream before failing; both print to stderr. The module checks what it
// can before GDCM reads a file (dicom_series.cpp: framing, attribute VRs, pixel data length, the
// codestream's own image size), and everything it cannot foresee is contained here: GDCM runs in a
// forked child with an address-space limit (release builds; sanitizers reserve terabytes of shadow
// memory, so sanitized builds go without), no core dumps, its stdout/stderr captured, watched for
// progress and killed on Ctrl-C. The voxels go straight into a memfd the parent maps afterwards
// (no copy); a signal, an exhausted budget or a stall becomes one InputError line naming the file
// GDCM was reading, with the first line GDCM/OpenJPEG printed.
//
// VOXLIGHT_DICOM_IN_PROCESS=1 runs GDCM in the calling process instead (debugging under gdb).
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <mutex>
#include <new>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/text.h"
#include "io/child_process.h"
#include "io/dicom_module.h"
#include "io/dicom_series.h"
#include "io/module_loader.h"
#include "io/slice_stack.h"

namespace voxlight::io::detail {

namespace {

namespace fs = std::filesystem;
namespace mod = dicom_module;

/// A child that reports nothing for this long is taken as hung inside GDCM and killed. Decoding
/// one slice of any real series takes well under a second; scanning thousands of headers over a
/// slow share may take longer, but the child reports each file it opens.
constexpr auto kStallLimit = std::chrono::seconds(30);
/// Address space the child may use beyond what it had at fork (the parent's mappings) and the
/// voxels: GDCM's per-slice buffers and the codecs' work memory.
constexpr std::size_t kChildHeadroomBytes = std::size_t(768) << 20;
/// Per slice, the child may use this many times the slice's decoded size on top (codec buffers).
constexpr std::size_t kChildSliceFactor = 16;
/// At most this much of the child's stderr is kept for the error message.
constexpr std::size_t kMaxCapturedBytes = 64 * 1024;

// --- Messages from the child: one kind byte, a uint32 length, the payload ----------------------
enum class Msg : char {
    Progress = 'P',     ///< double fraction
    Reading = 'F',      ///< path of the file GDCM is about to read
    Error = 'E',        ///< InputError: source, field, problem, fix
    Internal = 'X',     ///< another exception's what()
    OutOfMemory = 'M',  ///< std::bad_alloc: the budget (uint64 bytes) was exhausted
    Volume = 'V',       ///< success: VolumeHeader, then unit and description
};

/// The volume's fixed-size fields; the child is a fork of the parent, so raw bytes are exact.
struct VolumeHeader {
    core::Geometry geometry;
    core::VoxelType type;
    core::Modality modality;
    double slope, intercept;
    std::uint64_t bytes;
};

class Writer {
  public:
    explicit Writer(int fd) : fd_(fd) {}
    void send(Msg kind, const std::string& payload) const {
        std::string m(1, char(kind));
        const std::uint32_t n = std::uint32_t(payload.size());
        m.append(reinterpret_cast<const char*>(&n), sizeof n);
        m += payload;
        const char* p = m.data();
        std::size_t left = m.size();
        while (left > 0) {
            const ssize_t w = ::write(fd_, p, left);
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0) ::_exit(3);  // the parent is gone
            p += w, left -= std::size_t(w);
        }
    }
    static void field(std::string& out, const std::string& s) {
        const std::uint32_t n = std::uint32_t(s.size());
        out.append(reinterpret_cast<const char*>(&n), sizeof n);
        out += s;
    }

  private:
    int fd_;
};

/// Reads length-prefixed strings back out of a payload.
struct Reader {
    const std::string& s;
    std::size_t at = 0;
    std::string field() {
        std::uint32_t n = 0;
        if (at + sizeof n > s.size()) return {};
        std::memcpy(&n, s.data() + at, sizeof n);
        at += sizeof n;
        if (at + n > s.size()) n = std::uint32_t(s.size() - at);
        std::string out = s.substr(at, n);
        at += n;
        return out;
    }
};

/// Test seam (tests/io_dicom/test_dicom_hostile.cpp): VOXLIGHT_DICOM_CHILD_FAULT makes the child
/// fail in each way GDCM and OpenJPEG were seen to fail, so that the containment is tested apart
/// from the checks that now keep the known damaged files away from GDCM.
void injectFault(const fs::path& path) {
    const char* fault = std::getenv("VOXLIGHT_DICOM_CHILD_FAULT");
    if (!fault) return;
    const std::string f = fault;
    if (f == "abort") {
        std::fprintf(stderr,
                     "voxlight: ./Source/Fake/gdcmFake.h:236: void gdcm::Fake::Read(): Assertion "
                     "`Fragments.size()' failed.\n");
        std::abort();
    } else if (f == "segv") {
        ::raise(SIGSEGV);
    } else if (f == "hang") {
        for (;;) ::pause();
    } else if (f == "grow" || f == "alloc") {
        injectAllocationFault(f);
    } else if (f == "noise") {  // OpenJPEG's habit: error lines on stderr, then GDCM returns false
        std::fprintf(stderr, "[ERROR] Stream too short\n[ERROR] Failed to decode the codestream\n");
        throw InputError(path.string(), "PixelData", "GDCM cannot decode the pixel data");
    }
}

/// Seconds without news from the child before it is taken as hung (VOXLIGHT_DICOM_STALL_SECONDS
/// overrides kStallLimit, for tests).
std::chrono::seconds stallLimit() {
    if (const char* s = std::getenv("VOXLIGHT_DICOM_STALL_SECONDS")) {
        const int v = std::atoi(s);
        if (v > 0) return std::chrono::seconds(v);
    }
    return kStallLimit;
}

/// The child: run the module, report through `msgFd`, never return.
[[noreturn]] void runChild(const mod::Api& api, const fs::path& path, const ReadOptions& options,
                           int msgFd, int errFd, int memFd) {
    // GDCM's and OpenJPEG's printing goes to the parent's capture, not the user's terminal or the
    // JSON on stdout.
    ::dup2(errFd, STDOUT_FILENO);
    ::dup2(errFd, STDERR_FILENO);
    becomeReaderChild();
    const Writer out(msgFd);
    std::size_t budget = limitChildMemory(kChildHeadroomBytes);

    mod::Hooks hooks;
    hooks.reading = [&](const fs::path& f) { out.send(Msg::Reading, f.string()); };
    hooks.allocate = [&](std::size_t bytes, std::size_t sliceBytes) {
        if (::ftruncate(memFd, off_t(bytes)) != 0) throw std::bad_alloc();
        void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, memFd, 0);
        if (p == MAP_FAILED) throw std::bad_alloc();
        budget = limitChildMemory(kChildHeadroomBytes + kChildSliceFactor * sliceBytes);
        return std::shared_ptr<std::byte>(static_cast<std::byte*>(p),
                                          [bytes](std::byte* q) { ::munmap(q, bytes); });
    };
    const core::Progress progress(
        [&](const std::string&, double f) {
            out.send(Msg::Progress, std::string(reinterpret_cast<const char*>(&f), sizeof f));
        },
        nullptr);
    try {
        injectFault(path);
        const mod::SeriesResult r = api.readSeries(path, options, progress, hooks);
        const core::Volume& v = r.stack;
        VolumeHeader h{v.geometry(),        v.type(),
                       v.modality,          v.mapping.slope,
                       v.mapping.intercept, std::uint64_t(v.sizeBytes())};
        std::string payload(reinterpret_cast<const char*>(&h), sizeof h);
        Writer::field(payload, v.mapping.unit);
        Writer::field(payload, v.description);
        Writer::field(payload, r.irregularity);
        Writer::field(payload, std::string(reinterpret_cast<const char*>(r.slicePositions.data()),
                                           r.slicePositions.size() * sizeof(glm::dvec3)));
        out.send(Msg::Volume, payload);
    } catch (const InputError& e) {
        std::string payload;
        for (const std::string* s : {&e.source(), &e.field(), &e.problem(), &e.fix()})
            Writer::field(payload, *s);
        out.send(Msg::Error, payload);
    } catch (const std::bad_alloc&) {
        const std::uint64_t b = budget;
        out.send(Msg::OutOfMemory, std::string(reinterpret_cast<const char*>(&b), sizeof b));
    } catch (const std::exception& e) {
        out.send(Msg::Internal, e.what());
    } catch (...) {
        out.send(Msg::Internal, "unknown exception in the DICOM reader");
    }
    ::_exit(0);  // no atexit handlers, no stdio flush of the parent's buffers
}

/// The most telling line of what the child printed: an assertion, a sanitizer or OpenJPEG error,
/// else the first non-empty line; control characters escaped, cut to 240 characters.
std::string telltaleLine(const std::string& captured) {
    std::vector<std::string> lines;
    std::size_t start = 0;
    while (start < captured.size()) {
        std::size_t end = captured.find('\n', start);
        if (end == std::string::npos) end = captured.size();
        std::string line = captured.substr(start, end - start);
        while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
        if (!line.empty()) lines.push_back(line);
        start = end + 1;
    }
    if (lines.empty()) return {};
    // "prog: path/gdcmFile.h:236: signature: Assertion `cond' failed." → "gdcmFile.h:236: Assertion
    // `cond' failed."
    for (const auto& l : lines) {
        const std::size_t a = l.find("Assertion `");
        if (a == std::string::npos) continue;
        std::string where;
        const std::size_t colon = l.find(": ");
        if (colon != std::string::npos) {
            const std::size_t fileEnd = l.find(": ", colon + 2);
            if (fileEnd != std::string::npos && fileEnd < a) {
                where = l.substr(colon + 2, fileEnd - colon - 2);
                const std::size_t slash = where.rfind('/');
                if (slash != std::string::npos) where.erase(0, slash + 1);
                where += ": ";
            }
        }
        lines = {where + l.substr(a)};
        break;
    }
    std::string best = lines.front();
    for (const char* key : {"Assertion", "ERROR", "Error", "error"}) {
        bool found = false;
        for (const auto& l : lines)
            if (l.find(key) != std::string::npos) {
                best = l, found = true;
                break;
            }
        if (found) break;
    }
    std::string out;
    for (unsigned char c : best) {
        if (c < 0x20 || c == 0x7f) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\x%02X", c);
            out += buf;
        } else {
            out += char(c);
        }
        if (out.size() >= 240) {
            out += "...";
            break;
        }
    }
    if (lines.size() > 1) out += " [+" + std::to_string(lines.size() - 1) + " more line(s)]";
    return out;
}

std::string signalName(int sig) {
    switch (sig) {
        case SIGABRT:
            return "SIGABRT (an assertion in GDCM)";
        case SIGSEGV:
            return "SIGSEGV";
        case SIGBUS:
            return "SIGBUS";
        case SIGFPE:
            return "SIGFPE";
        case SIGILL:
            return "SIGILL";
        case SIGKILL:
            return "SIGKILL";
        default:
            return "signal " + std::to_string(sig);
    }
}

const mod::Api& dicomModule(const fs::path& path) {
    static std::once_flag once;
    static LoadedModule loaded;
    std::call_once(once,
                   [] { loaded = loadModule(mod::kFileName, mod::kEntryPoint, mod::kAbiVersion); });
    if (!loaded.api)
        throw InputError(path.string(), "dicom module",
                         "DICOM support (GDCM) is unavailable: " + loaded.error,
                         std::string("put ") + mod::kFileName +
                             " (built with voxlight) beside the voxlight executable");
    return *static_cast<const mod::Api*>(loaded.api);
}

[[noreturn]] void systemFailure(const fs::path& path, const char* what) {
    throw InputError(
        path.string(), "dicom",
        std::string("cannot start the DICOM decoder: ") + what + ": " + std::strerror(errno),
        "check the system's limits on processes and memory");
}

mod::SeriesResult readIsolated(const mod::Api& api, const fs::path& path,
                               const ReadOptions& options, const core::Progress& progress) {
    ChildProcess child;
    child.mem = ::memfd_create("voxlight-dicom", MFD_CLOEXEC);
    if (child.mem < 0) systemFailure(path, "memfd_create");
    int msgPipe[2], errPipe[2];
    if (::pipe2(msgPipe, O_CLOEXEC) != 0) systemFailure(path, "pipe");
    if (::pipe2(errPipe, O_CLOEXEC) != 0) {
        ::close(msgPipe[0]), ::close(msgPipe[1]);
        systemFailure(path, "pipe");
    }
    child.msg = msgPipe[0];
    child.err = errPipe[0];
    detail::awaitModuleLoads();  // no fork during a dlopen (module_loader.h)
    std::fflush(nullptr);        // nothing buffered is written twice (the loader may have printed)
    child.pid = ::fork();
    if (child.pid < 0) {
        ::close(msgPipe[1]), ::close(errPipe[1]);
        systemFailure(path, "fork");
    }
    if (child.pid == 0) {
        ::close(msgPipe[0]), ::close(errPipe[0]);
        runChild(api, path, options, msgPipe[1], errPipe[1], child.mem);
    }
    ::close(msgPipe[1]), ::close(errPipe[1]);

    std::string msgBuf, captured, result;
    Msg resultKind{};
    bool haveResult = false;
    fs::path reading = path;
    bool msgOpen = true, errOpen = true;
    auto lastNews = std::chrono::steady_clock::now();
    const auto stall = stallLimit();
    while (msgOpen || errOpen) {
        pollfd fds[2] = {{msgOpen ? child.msg : -1, POLLIN, 0},
                         {errOpen ? child.err : -1, POLLIN, 0}};
        const int n = ::poll(fds, 2, 100);
        progress.checkCancel();  // CancelledError: the guard kills the child
        if (n < 0 && errno != EINTR) systemFailure(path, "poll");
        if (std::chrono::steady_clock::now() - lastNews > stall) {
            throw InputError(
                reading.string(), "PixelData",
                "DICOM decoding failed (GDCM made no progress for " +
                    std::to_string(stall.count()) + " s and was stopped)",
                "the file is probably damaged; remove it from the folder or copy the series again");
        }
        char buf[65536];
        if (fds[1].revents) {
            const ssize_t r = ::read(child.err, buf, sizeof buf);
            if (r > 0 && captured.size() < kMaxCapturedBytes)
                captured.append(buf, std::min<std::size_t>(std::size_t(r),
                                                           kMaxCapturedBytes - captured.size()));
            if (r == 0 || (r < 0 && errno != EINTR && errno != EAGAIN)) errOpen = false;
        }
        if (fds[0].revents) {
            const ssize_t r = ::read(child.msg, buf, sizeof buf);
            if (r == 0 || (r < 0 && errno != EINTR && errno != EAGAIN)) msgOpen = false;
            if (r > 0) {
                lastNews = std::chrono::steady_clock::now();
                msgBuf.append(buf, std::size_t(r));
            }
            // Whole messages only.
            while (msgBuf.size() >= 5) {
                std::uint32_t len = 0;
                std::memcpy(&len, msgBuf.data() + 1, sizeof len);
                if (msgBuf.size() < 5 + std::size_t(len)) break;
                const Msg kind = Msg(msgBuf[0]);
                std::string payload = msgBuf.substr(5, len);
                msgBuf.erase(0, 5 + std::size_t(len));
                if (kind == Msg::Progress && payload.size() == sizeof(double)) {
                    double f = 0;
                    std::memcpy(&f, payload.data(), sizeof f);
                    progress.report("dicom", f);
                } else if (kind == Msg::Reading) {
                    reading = payload;
                } else {
                    resultKind = kind, result = std::move(payload), haveResult = true;
                }
            }
        }
    }
    const int status = child.wait();
    progress.checkCancel();

    const std::string noise = telltaleLine(captured);
    const std::string fix =
        "the file is damaged or uses an encoding GDCM cannot decode; remove it from the folder, "
        "copy the series again, or convert it with gdcmconv --raw";
    // The budget's refusal, however the child met it (budget: bytes, 0 = not known here).
    const auto overBudget = [&](std::uint64_t budget) {
        return InputError(reading.string(), "PixelData",
                          "DICOM decoding failed (GDCM needed more memory than the " +
                              (budget ? std::to_string(budget >> 20) + " MiB " : std::string()) +
                              "budget for this image" + (noise.empty() ? "" : ": " + noise) + ")",
                          fix);
    };
    if (!haveResult && WIFEXITED(status) && WEXITSTATUS(status) == kChildOverBudgetStatus)
        throw overBudget(0);
    if (!haveResult) {
        std::string why;
        if (WIFSIGNALED(status))
            why = "GDCM crashed with " + signalName(WTERMSIG(status));
        else if (WIFEXITED(status))
            why = "the decoder exited with status " + std::to_string(WEXITSTATUS(status));
        else
            why = "the decoder ended abnormally";
#ifdef VOXLIGHT_SANITIZED
        // A sanitizer report from voxlight's own code in the child is a bug, not bad input: let the
        // test or fuzzer see it.
        // An allocation the sanitizer's allocator refused is the budget's refusal (an
        // address-space cap refuses it in a release build).
        if (captured.find("allocator is out of memory") != std::string::npos ||
            captured.find("requested allocation size") != std::string::npos)
            throw overBudget(0);
        if (captured.find("runtime error:") != std::string::npos ||
            (captured.find("ERROR: AddressSanitizer") != std::string::npos &&
             captured.find("SEGV on unknown address") == std::string::npos))
            throw InternalError("sanitizer report in the DICOM decoder process:\n" + captured);
#endif
        throw InputError(
            reading.string(), "PixelData",
            "DICOM decoding failed (" + why + (noise.empty() ? "" : ": " + noise) + ")", fix);
    }
    Reader rd{result};
    switch (resultKind) {
        case Msg::Error: {
            const std::string source = rd.field(), field = rd.field(), problem = rd.field(),
                              fixText = rd.field();
            throw InputError(source, field, noise.empty() ? problem : problem + " (" + noise + ")",
                             fixText);
        }
        case Msg::OutOfMemory: {
            std::uint64_t budget = 0;
            if (result.size() == sizeof budget) std::memcpy(&budget, result.data(), sizeof budget);
            throw overBudget(budget);
        }
        case Msg::Internal:
            throw InternalError("DICOM reader: " + result);
        case Msg::Volume:
            break;
        default:
            throw InternalError("DICOM reader: unexpected message from the decoder process");
    }
    VolumeHeader h{};
    if (result.size() < sizeof h) throw InternalError("DICOM reader: short result message");
    std::memcpy(&h, result.data(), sizeof h);
    rd.at = sizeof h;
    const std::string unit = rd.field();
    const std::string description = rd.field();
    mod::SeriesResult r;
    r.irregularity = rd.field();
    const std::string positions = rd.field();
    if (positions.size() % sizeof(glm::dvec3) != 0)
        throw InternalError("DICOM reader: short slice position list");
    r.slicePositions.resize(positions.size() / sizeof(glm::dvec3));
    if (!positions.empty())
        std::memcpy(r.slicePositions.data(), positions.data(), positions.size());
    struct stat st {};
    if (::fstat(child.mem, &st) != 0 || std::uint64_t(st.st_size) != h.bytes || h.bytes == 0)
        throw InternalError("DICOM reader: the decoder's voxel buffer has the wrong size");
    void* p = ::mmap(nullptr, h.bytes, PROT_READ | PROT_WRITE, MAP_SHARED, child.mem, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    const std::size_t bytes = h.bytes;
    core::Volume v(h.geometry, h.type,
                   std::shared_ptr<std::byte>(static_cast<std::byte*>(p),
                                              [bytes](std::byte* q) { ::munmap(q, bytes); }));
    v.modality = h.modality;
    v.mapping.slope = h.slope;
    v.mapping.intercept = h.intercept;
    v.mapping.unit = unit;
    v.description = description;
    r.stack = std::move(v);
    return r;
}

/// Resamples an irregular stack (slice_stack.h) and says so in one warning line: what was found,
/// what was done, and how to refuse instead.
core::Volume regularize(mod::SeriesResult r, const fs::path& path, const core::Progress& progress) {
    if (r.slicePositions.empty()) return std::move(r.stack);
    const glm::ivec3 acquired = r.stack.dims();
    core::Volume v = resampleSliceStack(r.stack, r.slicePositions, path.string(), progress);
    r.stack = core::Volume();  // the acquired slices are no longer needed
    const core::Geometry& g = v.geometry();
    const double background = v.physicalRange()[0];  // every blend is ≥ the stack's minimum
    std::ostringstream w;
    w << std::setprecision(4) << path.string() << ": DICOM series with " << r.irregularity
      << "; resampled its " << acquired.z << " slices onto a regular grid of " << g.dims.z
      << " slices at " << g.spacing.z << " mm along the slice normal (" << g.dims.x << "x"
      << g.dims.y << " pixels, was " << acquired.x << "x" << acquired.y
      << "; outside the acquired slices: the series minimum " << background
      << (v.mapping.unit.empty() ? "" : " " + v.mapping.unit)
      << (v.modality == core::Modality::CT ? ", air" : "")
      << "); use --strict-geometry (scene: volume.strict_geometry) to refuse such series "
         "instead";
    v.warnings.push_back(oneLine(w.str()));  // the path may hold any bytes
    return v;
}

}  // namespace

core::Volume readDicomSeries(const std::filesystem::path& path, const ReadOptions& options,
                             const core::Progress& progress) {
    const mod::Api& api = dicomModule(path);
    const char* inProcess = std::getenv("VOXLIGHT_DICOM_IN_PROCESS");
    if (inProcess && std::strcmp(inProcess, "1") == 0)
        return regularize(api.readSeries(path, options, progress, mod::Hooks{}), path, progress);
    return regularize(readIsolated(api, path, options, progress), path, progress);
}

}  // namespace voxlight::io::detail
