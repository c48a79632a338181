// SPDX-License-Identifier: MIT
#pragma once
#include <string>

namespace voxlight {

/// `text` as one line of valid UTF-8: control characters (a CR or LF from a damaged header line)
/// and bytes that are not UTF-8 (binary garbage quoted from a file, a Latin-1 DICOM description)
/// become \xNN. Every InputError message goes through it (core/error.cpp), and so does text a
/// reader takes from a file.
std::string oneLine(const std::string& text);

}  // namespace voxlight
