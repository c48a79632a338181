// SPDX-License-Identifier: MIT
#pragma once
// A reader run in a forked child (volume_io.cpp's contained VTK reads, dicom_loader.cpp's GDCM
// decoding): the parent owns the child and the descriptors it reads it through.

#include <malloc.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(memory_sanitizer) || \
    __has_feature(thread_sanitizer)
#define VOXLIGHT_SANITIZED 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define VOXLIGHT_SANITIZED 1
#endif
#ifdef VOXLIGHT_SANITIZED
#include <sanitizer/common_interface_defs.h>
#endif

namespace voxlight::io {

/// A reading child's trim threshold: glibc's static default (128 KiB), undoing the parent's
/// retainFreedMemory for the child.
inline constexpr int kChildTrimThreshold = 128 * 1024;

/// Exit status of a reading child that went over its memory budget in a sanitized build
/// (limitChildMemory); its parent reports it as the out-of-memory refusal.
inline constexpr int kChildOverBudgetStatus = 86;

#ifdef VOXLIGHT_SANITIZED
/// What a sanitized child may hold beyond its budget: the sanitizer's shadow (1/8 of what is
/// touched), redzones and quarantine of freed memory (256 MiB by default).
inline constexpr std::size_t kSanitizedSlackBytes = std::size_t(512) << 20;

/// This process's resident bytes (/proc/self/statm), 0 when unknown.
inline std::size_t residentBytes() {
    std::size_t size = 0, resident = 0;
    std::ifstream("/proc/self/statm") >> size >> resident;
    return resident * std::size_t(::sysconf(_SC_PAGESIZE));
}
#endif

/// Caps this (child) process's address space at what it uses now plus `extra` bytes. Returns
/// `extra`, or 0 when no cap was set. Sanitized builds, whose shadow memory alone exceeds any
/// address-space cap, cap the resident memory instead (plus kSanitizedSlackBytes): a thread of
/// the child checks it every few milliseconds and ends the child with kChildOverBudgetStatus.
/// Without it a damaged JPEG header that made GDCM zero-fill 4.7 GB took 5 s in the fuzzers
/// (0.04 s in a release build, where the address-space cap refuses the allocation) and every
/// long dicom_series run stopped at such a "timeout" within minutes (5 December).
inline std::size_t limitChildMemory(std::size_t extra) {
#ifdef VOXLIGHT_SANITIZED
    static std::atomic<std::size_t> cap{0};
    cap = residentBytes() + extra + kSanitizedSlackBytes;
    static bool watching = false;  // the child is single-threaded until the watch starts
    if (!watching) {
        watching = true;
        std::thread([] {
            for (;;) {
                std::this_thread::sleep_for(std::chrono::milliseconds(5));
                const std::size_t now = residentBytes();
                if (now > cap) {
                    std::fprintf(stderr, "reader over its memory budget (%zu MiB resident)\n",
                                 now >> 20);
                    ::_exit(kChildOverBudgetStatus);
                }
            }
        }).detach();
    }
    return extra;
#else
    // Heap the parent freed but kept mapped (core::retainFreedMemory keeps up to 1 GiB) would be
    // reused inside the cap without growing the address space: hand back what can be first, so
    // the cap counts from what is in use.
    ::mallopt(M_TRIM_THRESHOLD, kChildTrimThreshold);
    ::malloc_trim(0);
    std::size_t pages = 0;
    std::ifstream("/proc/self/statm") >> pages;
    const std::size_t cap = pages * std::size_t(::sysconf(_SC_PAGESIZE)) + extra;
    rlimit r{};
    if (::getrlimit(RLIMIT_AS, &r) != 0) return 0;
    if (r.rlim_max != RLIM_INFINITY && cap > r.rlim_max) return 0;
    r.rlim_cur = cap;
    return ::setrlimit(RLIMIT_AS, &r) == 0 ? extra : 0;
#endif
}

/// Test seam shared by the reading children (tests/io/test_bad_input.cpp,
/// tests/io_dicom/test_dicom_hostile.cpp): the two ways their libraries were seen to ask for
/// memory a damaged file does not justify, so that the budget's refusal is tested apart from the
/// checks that now keep those files away. "alloc": one request of 64 GiB (what OpenJPEG asked
/// for, ×16); "grow": 8 GiB zero-filled as a vector grows (GDCM's ByteValue sized from a damaged
/// length) — more than any budget, less than RAM. Other names do nothing.
inline void injectAllocationFault(std::string_view fault) {
    static char* volatile sink;  // volatile: the allocation must not be optimised away
    if (fault == "alloc") {
        sink = new char[std::size_t(64) << 30];
        delete[] sink;
    } else if (fault == "grow") {
        std::vector<char> v;
        v.resize(std::size_t(8) << 30);
        sink = v.data();
    }
}

/// A reading child's first act: crashes end it plainly (default handlers, no core file, no
/// handler inherited from the parent: the CLI's Ctrl-C handler, a fuzzer's crash reporter); Ctrl-C
/// reaches the parent, which kills the child.
inline void becomeReaderChild() {
    ::signal(SIGINT, SIG_IGN);
    for (int sig : {SIGTERM, SIGABRT, SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGPIPE, SIGALRM, SIGXCPU})
        ::signal(sig, SIG_DFL);
    rlimit core{0, 0};
    ::setrlimit(RLIMIT_CORE, &core);
#ifdef VOXLIGHT_SANITIZED
    __sanitizer_set_death_callback(nullptr);
#endif
}

/// Kills (SIGKILL) and reaps the child unless it was reaped by wait(), and closes the
/// descriptors: whatever way the parent leaves (an error, Ctrl-C's CancelledError), no child and
/// no descriptor is left behind.
struct ChildProcess {
    pid_t pid = -1;
    int msg = -1;  ///< the child's messages (read end of a pipe)
    int err = -1;  ///< what the child printed (read end of a pipe), if captured separately
    int mem = -1;  ///< the memfd the child writes its result into

    ChildProcess() = default;
    ChildProcess(const ChildProcess&) = delete;
    ChildProcess& operator=(const ChildProcess&) = delete;
    ~ChildProcess() {
        if (pid > 0) {
            ::kill(pid, SIGKILL);
            wait();
        }
        for (int fd : {msg, err, mem})
            if (fd >= 0) ::close(fd);
    }
    /// Reaps the child; its wait status.
    int wait() {
        int status = 0;
        while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
        }
        pid = -1;
        return status;
    }
    /// Bytes the child has read so far (its /proc rchar), 0 when unknown.
    std::uint64_t bytesRead() const {
        std::ifstream io("/proc/" + std::to_string(pid) + "/io");
        std::string key;
        std::uint64_t value = 0;
        while (io >> key >> value)
            if (key == "rchar:") return value;
        return 0;
    }
};

}  // namespace voxlight::io
