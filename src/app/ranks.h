// SPDX-License-Identifier: MIT
#pragma once
// The ranks of an MPI launch (`mpirun -n K voxlight sweep|replay ...`): Open MPI through its
// module (mpi_module.h) when K > 1, otherwise one rank and no MPI at all. Rank 0 reports; the other
// ranks' stderr goes to /dev/null (every rank validates the same input and would print the same
// error), and their failures reach rank 0 through gather() (rankError / parseRankError).
#include <functional>
#include <string>
#include <vector>

#include "app/mpi_module.h"

namespace voxlight::app {

class Ranks {
  public:
    /// Starts MPI when launched by mpirun with more than one rank; InputError when this build
    /// cannot (no MPI module) or MPI fails to start.
    Ranks();
    Ranks(const Ranks&) = delete;
    Ranks& operator=(const Ranks&) = delete;
    ~Ranks();
    int rank() const { return rank_; }
    int size() const { return size_; }
    bool lead() const { return rank_ == 0; }
    /// True on every rank when `ok` is true on every rank (a barrier too).
    bool allTrue(bool ok) const;
    /// Rank 0 receives every rank's text in rank order; the others an empty vector.
    std::vector<std::string> gather(const std::string& mine) const;

  private:
    const mpi_module::Api* api_ = nullptr;
    int rank_ = 0, size_ = 1;
};

/// Runs this rank's share of the work. With one rank it is just `work()`; with more, a failure
/// (Ctrl-C, bad input, a bug) must not leave the other ranks waiting in gather(): it is returned
/// as one line, "!CODE message", for rank 0 to report. Returns "" when the work succeeded.
std::string runRankWork(const Ranks& ranks, const std::function<void()>& work);
/// Rank 0: the non-empty lines of every rank's gathered text, in rank order, into `lines`; each
/// failure line is printed ("voxlight: error: rank R: ...") and the first one's exit code returned
/// (0: every rank succeeded).
int collectRankLines(const std::vector<std::string>& all, std::vector<std::string>& lines);

}  // namespace voxlight::app
