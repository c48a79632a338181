// SPDX-License-Identifier: MIT
#pragma once
// A command's output files: every path checked before the work, all of them written beside their
// targets and committed together after it.
//
// checkOutputs() runs before any work and throws InputError (source "command line", field the
// option) for the first output that could not be written: a wrong extension, a missing or
// unwritable parent directory, a path that is a directory, or two options naming the same file
// (symlinks and hard links included).
//
// OutputFiles::write() runs a writer on a temporary file in the target's directory (same file
// system, so the final rename is atomic; the temporary's name is short and ends in the target's
// format suffix — ".png", ".nii.gz" — so writers that pick the format by extension still do). A writer that returns while
// the disk is full failed, whatever it says (libraries that ignore a failed write leave a short
// file and report success): that is an error naming the target. commit() renames every temporary
// into place only after all were written, each old target first kept under a second name (a hard
// link: the target never goes missing, and each replacement is one atomic rename) and removed
// only when the whole commit succeeded. Destroying an OutputFiles before commit() (an error or Ctrl-C
// unwinding) removes every temporary; a rename failing during commit() moves back every old file
// this commit replaced and removes the new ones, so a run leaves all of its outputs or none of
// them, and a failed run leaves the files that were there as they were. Errors name the option and
// the target, with the system's reason (never the temporary's name, never "Success"). A target
// that is a symlink to a file is written through (the file is replaced, the link stays), one that
// is a FIFO or device is refused; a replaced regular file keeps its permission bits.
#include <filesystem>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace voxlight::app {

struct OutputSpec {
    std::string option;                   ///< "--output", "--exr", … (named in errors)
    std::filesystem::path path;           ///< empty: the option was not given (skipped)
    std::vector<std::string> extensions;  ///< allowed name endings, lower case; empty: any
};

/// Checks every given output before the work; InputError naming the option on the first problem.
/// `inputs` (what the command reads: name as errors say it, path): an output that is one of them
/// would replace what it was made from (`compare a.png b.png --map a.png` overwrote a.png).
void checkOutputs(const std::vector<OutputSpec>& outputs,
                  const std::vector<std::pair<std::string, std::filesystem::path>>& inputs = {});

class OutputFiles {
  public:
    OutputFiles() = default;
    OutputFiles(const OutputFiles&) = delete;
    OutputFiles& operator=(const OutputFiles&) = delete;
    ~OutputFiles();  ///< removes every temporary not committed

    /// Calls `writer` with a fresh temporary path beside `target`. An InputError the writer raises
    /// about the temporary (or one of its own beside it) is rethrown naming `target`; a writer
    /// that leaves the disk full fails with core::noSpaceLeft(target), whatever it raised or not;
    /// any failure removes the temporary.
    void write(const std::filesystem::path& target, const std::string& option,
               const std::function<void(const std::filesystem::path&)>& writer);

    /// Renames every temporary onto its target, in the order written; see the header comment.
    void commit();

  private:
    struct Entry {
        std::filesystem::path temporary, target;  ///< target: a symlink's file, resolved
        std::string option;
        std::filesystem::path shown;  ///< the target as the command line gave it (errors)
    };
    std::vector<Entry> entries_;
};

/// Writes `text` and a final newline to `path`; InputError with the system's reason on failure.
void writeTextFile(const std::filesystem::path& path, const std::string& text);

}  // namespace voxlight::app
