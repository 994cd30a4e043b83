# Precompiled headers: Eigen, GoogleTest and the standard library make up about half of a
# translation unit's compile time, and every target parses them in every one of its files.
# Only headers from outside crumple are precompiled; a header that misses one of its includes
# still fails the consumer test, which compiles each installed header alone without them.
# Off under a compiler launcher by default: ccache caches builds that use a precompiled header
# only with `sloppiness=pch_defines,time_macros` (set it, then -DCRUMPLE_PCH=ON, to have both).
set(_crumple_pch_default ON)
if(CMAKE_CXX_COMPILER_LAUNCHER)
  set(_crumple_pch_default OFF)
endif()
option(CRUMPLE_PCH "Precompile the common external headers (faster clean builds)" ${_crumple_pch_default})

set(CRUMPLE_PCH_HEADERS
  <Eigen/Core> <Eigen/Geometry>
  <algorithm> <array> <atomic> <chrono> <cmath> <cstddef> <cstdint> <cstdio> <cstring>
  <filesystem> <functional> <limits> <memory> <mutex> <optional> <ostream> <span> <string>
  <string_view> <utility> <vector>)

# crumple_precompile(TARGET [HEADER...]): TARGET's files compile against one precompiled
# CRUMPLE_PCH_HEADERS plus the given headers. Only for targets of 5 files or more: building the
# precompiled header costs about 11 CPU s (gcc 12), and each file saves 3 to 5 s.
function(crumple_precompile target)
  get_target_property(_sources ${target} SOURCES)
  list(FILTER _sources INCLUDE REGEX "\\.cpp$")
  list(LENGTH _sources _count)
  if(CRUMPLE_PCH AND _count GREATER_EQUAL 5)
    target_precompile_headers(${target} PRIVATE ${CRUMPLE_PCH_HEADERS} ${ARGN})
  endif()
endfunction()

# crumple_reuse_pch(TARGET OWNER): TARGET's files use OWNER's precompiled header (one build of it
# for every test program; their compile options differ only in macros the header never uses).
function(crumple_reuse_pch target owner)
  if(CRUMPLE_PCH)
    target_precompile_headers(${target} REUSE_FROM ${owner})
  endif()
endfunction()
