# The installed headers are the public ones (src/CMakeLists.txt, CRUMPLE_INTERNAL_HEADERS):
# known internal headers are absent, known public ones present, and no installed header
# includes a crumple header that was not installed. Variable: PREFIX (an install prefix).
get_filename_component(PREFIX "${PREFIX}" ABSOLUTE)
file(GLOB_RECURSE _installed RELATIVE "${PREFIX}" "${PREFIX}/*.hpp")
foreach(_internal detect/gather.hpp detect/stochastic_engine.hpp detect/narrow_phase.hpp
                  detect/exact/narrow_frame.hpp io/io_detail.hpp io/ply_detail.hpp
                  detect/hybrid_detail.hpp detect/broad_phase/kdop_tree_detail.hpp)
  if(_installed MATCHES "crumple/${_internal}")
    message(FATAL_ERROR "internal header crumple/${_internal} was installed")
  endif()
endforeach()
foreach(_public detect/detector.hpp detect/exact_detector.hpp detect/broad_phase/broad_phase.hpp
                mesh/mesh.hpp io/mesh_io.hpp render/colouring.hpp sim/scene.hpp)
  if(NOT _installed MATCHES "crumple/${_public}")
    message(FATAL_ERROR "public header crumple/${_public} was not installed")
  endif()
endforeach()
foreach(_h IN LISTS _installed)
  string(REGEX REPLACE "crumple/.*$" "" _include_dir "${_h}")  # relative: no user folder in it
  file(STRINGS "${PREFIX}/${_h}" _includes REGEX "^#include <crumple/")
  foreach(_line IN LISTS _includes)
    string(REGEX REPLACE "^#include <([^>]+)>.*$" "\\1" _included "${_line}")
    if(NOT EXISTS "${PREFIX}/${_include_dir}${_included}")
      message(FATAL_ERROR "installed header ${_h} includes ${_included}, which is not installed")
    endif()
  endforeach()
endforeach()
