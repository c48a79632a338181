# SPDX-License-Identifier: MIT
# Writes OUTPUT: a header with each GLSL file of SHADERS as a C++ raw string constant named after
# the file (raycast.frag → kRaycastFrag), so the binary carries its shaders whatever the working
# directory. Run at build time (add_custom_command), so an edited shader rebuilds the header.
set(out "// Generated from shaders/ by cmake/embed_shaders.cmake: do not edit.\n#pragma once\n\n")
string(APPEND out "namespace voxlight::viewer::shaders {\n")
foreach(file IN LISTS SHADERS)
  get_filename_component(base "${file}" NAME_WE)
  get_filename_component(ext "${file}" EXT)
  string(SUBSTRING "${ext}" 1 -1 ext)
  string(SUBSTRING "${base}" 0 1 first)
  string(TOUPPER "${first}" first)
  string(SUBSTRING "${base}" 1 -1 rest)
  string(SUBSTRING "${ext}" 0 1 efirst)
  string(TOUPPER "${efirst}" efirst)
  string(SUBSTRING "${ext}" 1 -1 erest)
  file(READ "${file}" text)
  string(APPEND out "inline constexpr const char* k${first}${rest}${efirst}${erest} = R\"glsl(${text})glsl\";\n")
endforeach()
string(APPEND out "}  // namespace voxlight::viewer::shaders\n")
file(WRITE "${OUTPUT}.tmp" "${out}")
file(COPY_FILE "${OUTPUT}.tmp" "${OUTPUT}" ONLY_IF_DIFFERENT)
