# Find METIS 5 (libmetis-dev). Defines METIS_FOUND and the target METIS::METIS.
find_path(METIS_INCLUDE_DIR NAMES metis.h)
find_library(METIS_LIBRARY NAMES metis)

include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(METIS REQUIRED_VARS METIS_INCLUDE_DIR METIS_LIBRARY)

if(METIS_FOUND)
  file(STRINGS "${METIS_INCLUDE_DIR}/metis.h" _idx REGEX "^#define IDXTYPEWIDTH")
  if(NOT _idx MATCHES "32")
    message(FATAL_ERROR "METIS must use 32-bit idx_t (Debian's libmetis-dev does): ${_idx}")
  endif()
  if(NOT TARGET METIS::METIS)
    add_library(METIS::METIS INTERFACE IMPORTED)
    set_target_properties(METIS::METIS PROPERTIES
      INTERFACE_INCLUDE_DIRECTORIES "${METIS_INCLUDE_DIR}"
      INTERFACE_LINK_LIBRARIES "${METIS_LIBRARY}")
  endif()
endif()
mark_as_advanced(METIS_INCLUDE_DIR METIS_LIBRARY)
