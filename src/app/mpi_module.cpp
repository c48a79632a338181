// SPDX-License-Identifier: MIT
// libvoxlight_mpi.so: the few Open MPI calls `voxlight sweep` makes (mpi_module.h).
#include "app/mpi_module.h"

#include <dlfcn.h>
// The C API only: Open MPI's deprecated C++ bindings would need libmpi_cxx.
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>

namespace {
using voxlight::app::mpi_module::Api;

bool init(int* rank, int* size, std::string* error) {
    // Open MPI's components are plugins that dlopen and expect libmpi's symbols in the global
    // namespace, but the module loader opens this module (and so libmpi) RTLD_LOCAL: promote
    // libmpi to global first, or MPI_Init fails to open its components.
    Dl_info info{};
    if (::dladdr(reinterpret_cast<void*>(&MPI_Init_thread), &info) && info.dli_fname)
        ::dlopen(info.dli_fname, RTLD_NOW | RTLD_GLOBAL | RTLD_NOLOAD);
    int provided = 0;
    if (MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS) {
        *error = "MPI_Init_thread failed";
        return false;
    }
    MPI_Comm_rank(MPI_COMM_WORLD, rank);
    MPI_Comm_size(MPI_COMM_WORLD, size);
    return true;
}

void finalize() {
    int done = 0;
    MPI_Finalized(&done);
    if (!done) MPI_Finalize();
}

bool allTrue(bool ok) {
    int mine = ok ? 1 : 0, all = 0;
    MPI_Allreduce(&mine, &all, 1, MPI_INT, MPI_LAND, MPI_COMM_WORLD);
    return all != 0;
}

void gather(const std::string& mine, std::vector<std::string>* all) {
    int rank = 0, size = 1;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
    int length = int(mine.size());
    const auto n = static_cast<std::size_t>(size);
    std::vector<int> lengths(n), offsets(n);
    MPI_Gather(&length, 1, MPI_INT, lengths.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
    std::string joined;
    if (rank == 0) {
        int at = 0;
        for (int r = 0; r < size; ++r) offsets[std::size_t(r)] = at, at += lengths[std::size_t(r)];
        joined.resize(std::size_t(at));
    }
    MPI_Gatherv(mine.data(), length, MPI_CHAR, joined.data(), lengths.data(), offsets.data(),
                MPI_CHAR, 0, MPI_COMM_WORLD);
    if (rank == 0) {
        all->clear();
        for (int r = 0; r < size; ++r)
            all->push_back(joined.substr(std::size_t(offsets[std::size_t(r)]),
                                         std::size_t(lengths[std::size_t(r)])));
    }
}

[[noreturn]] void abortAll(int code) {
    MPI_Abort(MPI_COMM_WORLD, code);
    __builtin_unreachable();
}

const Api kApi = {
    voxlight::app::mpi_module::kAbiVersion, init, finalize, allTrue, gather, abortAll};
}  // namespace

extern "C" __attribute__((visibility("default"))) const void* voxlight_mpi_module() {
    return &kApi;
}
