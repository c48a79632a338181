// SPDX-License-Identifier: MIT
#pragma once
// The seam between `voxlight sweep` and Open MPI (libvoxlight_mpi.so, built from mpi_module.cpp
// when Debian's libopenmpi-dev is installed).
//
// Why a module: libmpi maps a dozen libraries (Open PAL, hwloc, PMIx, ...) and, linked into the
// executable, every voxlight process would load them before main(); only a sweep launched by
// `mpirun -n K voxlight sweep ...` needs them, so cmd_sweep.cpp opens the module then
// (io/module_loader.h). Both sides come from the same build, so std::string may cross;
// kAbiVersion guards against a stale module left beside a newer executable.
#include <string>
#include <vector>

namespace voxlight::app::mpi_module {

/// Bumped whenever Api changes layout or meaning.
inline constexpr int kAbiVersion = 1;
inline constexpr const char* kFileName = "libvoxlight_mpi.so";
inline constexpr const char* kEntryPoint = "voxlight_mpi_module";

struct Api {
    int abiVersion;
    /// MPI_Init_thread (funneled: only the main thread calls MPI); this rank and the number of
    /// ranks. Returns false with `error` set when MPI cannot start.
    bool (*init)(int* rank, int* size, std::string* error);
    void (*finalize)();
    /// True on every rank when `ok` is true on every rank (MPI_Allreduce, logical and).
    bool (*allTrue)(bool ok);
    /// Rank 0 receives every rank's `mine` in rank order in `all`; other ranks receive nothing.
    void (*gather)(const std::string& mine, std::vector<std::string>* all);
    /// Ends every rank (MPI_Abort) with `code`.
    void (*abort)(int code);
};

}  // namespace voxlight::app::mpi_module
