// SPDX-License-Identifier: MIT
#pragma once
// Internal to io/: loading the modules that keep heavy third-party libraries out of start-up.
//
// OpenImageIO (~280 shared libraries) and GDCM (which builds its whole DICOM dictionary in static
// constructors) would otherwise be mapped, relocated and initialised before main() in every voxlight
// process, whether or not it reads an image or a DICOM series. They live in MODULE libraries instead,
// opened here on first use.
//
// A module exports one `extern "C" const Api* <entryPoint>()`; its Api struct starts with
// `int abiVersion`, compared with the version the caller was compiled against, so a stale module
// left beside a newer executable is refused instead of called.
#include <string>

namespace voxlight::io::detail {

struct LoadedModule {
    const void* api = nullptr;  ///< what the entry point returned; null when loading failed
    std::string error;          ///< why api is null: every place tried and what went wrong there
};

/// Looks `fileName` up beside the running executable (/proc/self/exe: an installed or copied
/// voxlight), then in the directory this build put the modules in (tests run from
/// build/tests/<lib>/), dlopens the first that exists and returns its entry point's result.
/// Never throws; the handle is never closed (the libraries keep process-wide state). Not cached:
/// callers keep the result in a function-local static under std::call_once.
LoadedModule loadModule(const char* fileName, const char* entryPoint, int abiVersion);

/// Module loads are counted — every loadModule call, and a background preload
/// (io::ImageModulePreload) from before its thread starts: fork() while one runs on another
/// thread (the preload; the viewer's scene loads run on their own threads) would copy a process
/// whose dynamic loader is part-way through a dlopen, its lock held by a thread the child does not
/// have (a child that then loads or unwinds could deadlock), and the parent's relocation writes
/// would each copy a page the child shares. The reading children's fork sites call
/// awaitModuleLoads() first (never from inside a load: no fork happens there).
void beginModuleLoad();
void endModuleLoad();
void awaitModuleLoads();

/// The counter's three operations as one value. A module built with its own copy of this file
/// (libvoxlight_volume_vtk.so: it loads the DICOM module and forks the reading children) would
/// otherwise count in, and wait on, a counter of its own that io's loads never raise; io hands
/// the module this process's counter right after loading it (volume_module::Api::useLoadCounter),
/// before anything in the module can load or fork.
struct LoadCounter {
    void (*begin)();
    void (*end)();
    void (*await)();
};
/// This copy's own counter.
LoadCounter ownLoadCounter();
/// From now on this copy's begin/end/await forward to `counter` (another copy's own).
void useLoadCounter(const LoadCounter& counter);

}  // namespace voxlight::io::detail
