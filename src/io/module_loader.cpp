// SPDX-License-Identifier: MIT
#include "io/module_loader.h"

#include <dlfcn.h>

#include <atomic>
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <system_error>
#include <vector>

namespace voxlight::io::detail {

namespace {
struct ModuleLoads {
    std::mutex mutex;
    std::condition_variable done;
    int running = 0;
};
ModuleLoads& moduleLoads() {
    static ModuleLoads b;
    return b;
}
const LoadCounter& counter();  // below: this copy's own, or the one handed over

std::vector<std::filesystem::path> moduleDirectories() {
    std::vector<std::filesystem::path> dirs;
    std::error_code ec;
    const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (!ec) dirs.push_back(exe.parent_path());
#ifdef VOXLIGHT_MODULE_BUILD_DIR
    const std::filesystem::path built = VOXLIGHT_MODULE_BUILD_DIR;
    if (dirs.empty() || !std::filesystem::equivalent(dirs.front(), built, ec))
        dirs.push_back(built);
#endif
    return dirs;
}
}  // namespace

LoadedModule loadModule(const char* fileName, const char* entryPoint, int abiVersion) {
    using Entry = const void* (*)();
    // Counted while it runs (module_loader.h): a fork on another thread waits for it. The counter
    // is looked up once, so the load ends on the counter it began on.
    const LoadCounter& loads = counter();
    loads.begin();
    struct Counted {
        const LoadCounter& loads;
        ~Counted() { loads.end(); }
    } counted{loads};
    LoadedModule m;
    std::string tried;
    for (const auto& dir : moduleDirectories()) {
        const std::filesystem::path path = dir / fileName;
        if (!tried.empty()) tried += ", ";
        std::error_code ec;
        if (!std::filesystem::exists(path, ec)) {
            tried += path.string() + " (not found)";
            continue;
        }
        // RTLD_LOCAL: the module's libraries do not join the global symbol namespace.
        void* handle = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
        if (!handle) {
            const char* err = ::dlerror();
            tried += path.string() + " (" + (err ? err : "dlopen failed") + ")";
            continue;
        }
        const auto entry = reinterpret_cast<Entry>(::dlsym(handle, entryPoint));
        const void* api = entry ? entry() : nullptr;
        if (!api) {
            tried += path.string() + " (no entry point " + entryPoint + ")";
            ::dlclose(handle);
            continue;
        }
        // Every module's Api struct starts with its int abiVersion (module_loader.h).
        const int found = *static_cast<const int*>(api);
        if (found != abiVersion) {
            tried += path.string() + " (ABI version " + std::to_string(found) + ", expected " +
                     std::to_string(abiVersion) + ": a stale module from another build)";
            ::dlclose(handle);
            continue;
        }
        m.api = api;
        return m;
    }
    m.error = "tried " + tried;
    return m;
}

namespace {
void ownBegin() {
    ModuleLoads& b = moduleLoads();
    const std::lock_guard<std::mutex> lock(b.mutex);
    ++b.running;
}

void ownEnd() {
    ModuleLoads& b = moduleLoads();
    {
        const std::lock_guard<std::mutex> lock(b.mutex);
        --b.running;
    }
    b.done.notify_all();
}

void ownAwait() {
    ModuleLoads& b = moduleLoads();
    std::unique_lock<std::mutex> lock(b.mutex);
    b.done.wait(lock, [&] { return b.running == 0; });
}

/// The counter begin/end/await use: this copy's own until useLoadCounter hands over another.
/// Set once, before the module's code runs (module_loader.h); atomic so that a reader on another
/// thread never sees a torn pointer.
std::atomic<const LoadCounter*> sharedCounter{nullptr};
const LoadCounter kOwn{&ownBegin, &ownEnd, &ownAwait};
const LoadCounter& counter() {
    const LoadCounter* c = sharedCounter.load(std::memory_order_acquire);
    return c ? *c : kOwn;
}
}  // namespace

void beginModuleLoad() { counter().begin(); }
void endModuleLoad() { counter().end(); }
void awaitModuleLoads() { counter().await(); }

LoadCounter ownLoadCounter() { return kOwn; }

void useLoadCounter(const LoadCounter& c) {
    // Kept for the process's life: the handed-over functions are the host's, never unloaded.
    static const LoadCounter kept = c;
    if (c.begin == &ownBegin) return;  // the same copy (io loading a module it is linked with)
    sharedCounter.store(&kept, std::memory_order_release);
}

}  // namespace voxlight::io::detail
