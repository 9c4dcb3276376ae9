# pFUnit for the unit tests, found or built once.
#
# 1. find_package(PFUNIT): a pFUnit the user installed (CMAKE_PREFIX_PATH or PFUNIT_DIR).
# 2. Otherwise pFUnit 4.14.0 is built at configure time into a cache folder
#    outside the build tree, so that it survives `rm -rf build-*` and later
#    configures reuse it (a stamp file marks a finished install):
#      FETICONTACT_PFUNIT_CACHE (cache variable or environment variable), or
#      ${PROJECT_SOURCE_DIR}/.cache/pfunit-4.14.0-<hash of compiler and MPI>
#    Sources: the archive ${PROJECT_SOURCE_DIR}/../shared/third_party/pFUnit-4.14.0.tar.gz
#    when it exists (offline machines), otherwise the upstream release of the
#    same tag, FETICONTACT_PFUNIT_URL.
# 3. When neither works (offline, no archive, a failed build), the configure
#    goes on with a warning and every pFUnit test is registered as a test that
#    reports itself SKIPPED with the reason (CTest "Not Run"), never passed;
#    so are the tests that check what a pFUnit test writes (tests/io).
#    Unless pFUnit is required: FETICONTACT_REQUIRE_PFUNIT=ON (CMake or
#    environment variable), which is the default in CI (environment CI=true):
#    then the configure, and so tools/test.sh, fails with the reason.
set(FETICONTACT_PFUNIT_VERSION 4.14.0)
set(FETICONTACT_PFUNIT_AVAILABLE OFF)
set(FETICONTACT_PFUNIT_MISSING "")

# Required (a failure to find or build it fails the configure) in CI or when asked: the CMake
# option FETICONTACT_REQUIRE_PFUNIT, or the environment variable of that name (a true value), or
# the environment variable CI (true, 1, yes, on). The environment is read at every configure and
# never stored in the cache, so a build folder configured once in CI or with the variable does
# not keep requiring pFUnit later.
option(FETICONTACT_REQUIRE_PFUNIT "Fail the configure when pFUnit can be neither found nor built" OFF)
set(_fc_pf_true "^([Tt][Rr][Uu][Ee]|1|[Yy][Ee][Ss]|[Oo][Nn])$")
set(_fc_pf_required ${FETICONTACT_REQUIRE_PFUNIT})
set(_fc_pf_ci_note "")
if("$ENV{FETICONTACT_REQUIRE_PFUNIT}" MATCHES "${_fc_pf_true}")
  set(_fc_pf_required ON)
  set(_fc_pf_ci_note ", from the environment")
elseif("$ENV{CI}" MATCHES "${_fc_pf_true}")
  set(_fc_pf_required ON)
  set(_fc_pf_ci_note ", the default with CI=$ENV{CI}")
endif()

# pFUnit could not be had: the tests that need it skip, unless it is required.
macro(_fc_pf_unavailable reason)
  # the reason goes into the skip message of every pFUnit test (a `sh -c '...'` command): no quotes,
  # no list separators
  set(FETICONTACT_PFUNIT_MISSING "${reason}")
  string(REGEX REPLACE "[\"';`$\\]" " " FETICONTACT_PFUNIT_MISSING "${FETICONTACT_PFUNIT_MISSING}")
  if(_fc_pf_required)
    message(FATAL_ERROR "pFUnit: ${reason}; pFUnit is required (FETICONTACT_REQUIRE_PFUNIT=ON"
      "${_fc_pf_ci_note}): the pFUnit tests cannot run. Install pFUnit ${FETICONTACT_PFUNIT_VERSION} "
      "(-DCMAKE_PREFIX_PATH=<its prefix>), put its archive in ../shared/third_party, or set "
      "FETICONTACT_PFUNIT_URL.")
  endif()
  message(WARNING "pFUnit: ${reason}; the pFUnit tests and the tests that read their files will report "
    "themselves skipped. Install pFUnit ${FETICONTACT_PFUNIT_VERSION} and pass "
    "-DCMAKE_PREFIX_PATH=<its prefix>, or set FETICONTACT_PFUNIT_URL (FETICONTACT_REQUIRE_PFUNIT=ON makes "
    "this an error, as in CI).")
endmacro()

# feticontact_add_pfunit_test(<name> SOURCES <x.pf>... [LIBS <targets>] MAX_PES <n>
#                             [LABELS <labels>] [TIMEOUT <s>] [DEFINITIONS <defs>])
# A pFUnit test executable <name> from .pf modules, registered as one CTest
# test run as `mpiexec -n <n>` (pFUnit runs each @mpitest on the npes it lists,
# each at most <n>), with the environment of the other tests (root allowed,
# oversubscription) and the layer's label.
function(feticontact_add_pfunit_test name)
  cmake_parse_arguments(T "" "MAX_PES;TIMEOUT" "SOURCES;LIBS;LABELS;DEFINITIONS" ${ARGN})
  if(NOT T_MAX_PES)
    set(T_MAX_PES 1)
  endif()
  if(NOT T_TIMEOUT)
    set(T_TIMEOUT 300)
  endif()
  if(NOT FETICONTACT_PFUNIT_AVAILABLE)
    add_test(NAME ${name} COMMAND sh -c "echo 'SKIPPED: ${name}: pFUnit is not available (${FETICONTACT_PFUNIT_MISSING})'; exit 77")
    set_tests_properties(${name} PROPERTIES SKIP_RETURN_CODE 77 LABELS "pfunit;${T_LABELS}")
    return()
  endif()
  set(MPIEXEC_PREFLAGS --oversubscribe --bind-to none)
  add_pfunit_ctest(${name} TEST_SOURCES ${T_SOURCES} LINK_LIBRARIES ${T_LIBS}
                   MAX_PES ${T_MAX_PES} LABELS pfunit ${T_LABELS})
  target_compile_options(${name} PRIVATE -ffree-line-length-none)
  if(T_DEFINITIONS)
    target_compile_definitions(${name} PRIVATE ${T_DEFINITIONS})
  endif()
  set_tests_properties(${name} PROPERTIES TIMEOUT ${T_TIMEOUT} PROCESSORS ${T_MAX_PES}
                       ENVIRONMENT "${FETICONTACT_TEST_ENV}")
endfunction()

# The upstream release asset (with its submodules) is named pFUnit-v<version>.tar
# since 4.2.3 (pFUnit-<version>.tar before); the archive's top folder is found by
# its CMakeLists.txt, whatever its name.
set(FETICONTACT_PFUNIT_URL
    "https://github.com/Goddard-Fortran-Ecosystem/pFUnit/releases/download/v${FETICONTACT_PFUNIT_VERSION}/pFUnit-v${FETICONTACT_PFUNIT_VERSION}.tar"
    CACHE STRING "Upstream pFUnit release archive, downloaded when neither an installed pFUnit nor the local archive is found")
if(DEFINED ENV{FETICONTACT_PFUNIT_URL})
  set(FETICONTACT_PFUNIT_URL "$ENV{FETICONTACT_PFUNIT_URL}" CACHE STRING "" FORCE)   # the environment wins
endif()

# The cache folder: one per compiler (id, version, path) and MPI compiler wrapper,
# since Fortran module files are compiler-specific.
if(NOT FETICONTACT_PFUNIT_CACHE AND DEFINED ENV{FETICONTACT_PFUNIT_CACHE})
  set(FETICONTACT_PFUNIT_CACHE "$ENV{FETICONTACT_PFUNIT_CACHE}")
endif()
if(NOT FETICONTACT_PFUNIT_CACHE)
  string(MD5 _fc_pf_hash
    "${CMAKE_Fortran_COMPILER_ID};${CMAKE_Fortran_COMPILER_VERSION};${CMAKE_Fortran_COMPILER};${MPI_Fortran_COMPILER};${MPI_Fortran_LIBRARIES}")
  string(SUBSTRING "${_fc_pf_hash}" 0 10 _fc_pf_hash)
  set(FETICONTACT_PFUNIT_CACHE
      "${PROJECT_SOURCE_DIR}/.cache/pfunit-${FETICONTACT_PFUNIT_VERSION}-${CMAKE_Fortran_COMPILER_ID}-${CMAKE_Fortran_COMPILER_VERSION}-${_fc_pf_hash}")
endif()
set(FETICONTACT_PFUNIT_CACHE "${FETICONTACT_PFUNIT_CACHE}" CACHE PATH "Folder where pFUnit is built and installed once")
set(_fc_pf_root "${FETICONTACT_PFUNIT_CACHE}")
set(_fc_pf_prefix "${_fc_pf_root}/install")
set(_fc_pf_stamp "${_fc_pf_prefix}/feticontact-pfunit.stamp")

find_package(PFUNIT QUIET)
if(PFUNIT_FOUND)
  string(FIND "${PFUNIT_DIR}" "${_fc_pf_prefix}/" _fc_pf_at)
  if(_fc_pf_at EQUAL 0)
    message(STATUS "pFUnit: reusing the pFUnit ${PFUNIT_VERSION} built in ${_fc_pf_prefix}")
  else()
    message(STATUS "pFUnit: using the installed pFUnit ${PFUNIT_VERSION} (${PFUNIT_DIR})")
  endif()
  set(FETICONTACT_PFUNIT_AVAILABLE ON)
  return()
endif()


file(MAKE_DIRECTORY "${_fc_pf_root}")
# Two configures at once (two build folders) must not build into the same folder.
file(LOCK "${_fc_pf_root}/.lock" GUARD FILE TIMEOUT 1800 RESULT_VARIABLE _fc_pf_lock)
if(NOT _fc_pf_lock EQUAL 0)
  message(FATAL_ERROR "pFUnit: cannot lock ${_fc_pf_root}/.lock: ${_fc_pf_lock}")
endif()

if(EXISTS "${_fc_pf_stamp}")
  message(STATUS "pFUnit: reusing the pFUnit ${FETICONTACT_PFUNIT_VERSION} built in ${_fc_pf_prefix}")
else()
  set(_fc_pf_archive "${PROJECT_SOURCE_DIR}/../shared/third_party/pFUnit-${FETICONTACT_PFUNIT_VERSION}.tar.gz")
  if(EXISTS "${_fc_pf_archive}")
    get_filename_component(_fc_pf_archive "${_fc_pf_archive}" REALPATH)
    message(STATUS "pFUnit: not installed; building pFUnit ${FETICONTACT_PFUNIT_VERSION} from ${_fc_pf_archive} into ${_fc_pf_prefix} (once, about 2 minutes on 2 idle cores; log: ${_fc_pf_root}/build.log)")
  else()
    set(_fc_pf_archive "${_fc_pf_root}/pFUnit-${FETICONTACT_PFUNIT_VERSION}.tar")
    if(NOT EXISTS "${_fc_pf_archive}")
      message(STATUS "pFUnit: not installed; downloading ${FETICONTACT_PFUNIT_URL}")
      file(DOWNLOAD "${FETICONTACT_PFUNIT_URL}" "${_fc_pf_archive}.part" STATUS _fc_pf_dl TLS_VERIFY ON)
      list(GET _fc_pf_dl 0 _fc_pf_dl_code)
      if(NOT _fc_pf_dl_code EQUAL 0)
        file(REMOVE "${_fc_pf_archive}.part")
        file(LOCK "${_fc_pf_root}/.lock" RELEASE)
        _fc_pf_unavailable("download of ${FETICONTACT_PFUNIT_URL} failed (${_fc_pf_dl})")
        return()
      endif()
      file(RENAME "${_fc_pf_archive}.part" "${_fc_pf_archive}")
    endif()
    message(STATUS "pFUnit: building pFUnit ${FETICONTACT_PFUNIT_VERSION} from ${_fc_pf_archive} into ${_fc_pf_prefix} (once, about 2 minutes on 2 idle cores; log: ${_fc_pf_root}/build.log)")
  endif()

  file(REMOVE_RECURSE "${_fc_pf_root}/src" "${_fc_pf_root}/build" "${_fc_pf_prefix}")
  file(ARCHIVE_EXTRACT INPUT "${_fc_pf_archive}" DESTINATION "${_fc_pf_root}/src")
  file(GLOB _fc_pf_top LIST_DIRECTORIES true "${_fc_pf_root}/src/*/CMakeLists.txt")
  list(GET _fc_pf_top 0 _fc_pf_top)
  get_filename_component(_fc_pf_src "${_fc_pf_top}" DIRECTORY)

  set(_fc_pf_log "${_fc_pf_root}/build.log")
  set(_fc_pf_gen -G "${CMAKE_GENERATOR}")
  if(CMAKE_MAKE_PROGRAM)
    list(APPEND _fc_pf_gen "-DCMAKE_MAKE_PROGRAM=${CMAKE_MAKE_PROGRAM}")
  endif()
  foreach(_fc_pf_step configure build install)
    if(_fc_pf_step STREQUAL "configure")
      set(_fc_pf_cmd ${CMAKE_COMMAND} -S "${_fc_pf_src}" -B "${_fc_pf_root}/build" ${_fc_pf_gen}
          -DCMAKE_BUILD_TYPE=Release
          "-DCMAKE_Fortran_COMPILER=${CMAKE_Fortran_COMPILER}"
          "-DCMAKE_C_COMPILER=${CMAKE_C_COMPILER}"
          "-DCMAKE_INSTALL_PREFIX=${_fc_pf_prefix}"
          -DSKIP_OPENMP=YES -DSKIP_FHAMCREST=YES -DSKIP_ROBUST=YES)
    elseif(_fc_pf_step STREQUAL "build")
      set(_fc_pf_cmd ${CMAKE_COMMAND} --build "${_fc_pf_root}/build" -j 2)
    else()
      set(_fc_pf_cmd ${CMAKE_COMMAND} --install "${_fc_pf_root}/build")
    endif()
    execute_process(COMMAND ${_fc_pf_cmd} RESULT_VARIABLE _fc_pf_rc
                    OUTPUT_VARIABLE _fc_pf_out ERROR_VARIABLE _fc_pf_out)
    file(APPEND "${_fc_pf_log}" "== ${_fc_pf_step}\n${_fc_pf_out}\n")
    if(NOT _fc_pf_rc EQUAL 0)
      file(LOCK "${_fc_pf_root}/.lock" RELEASE)
      _fc_pf_unavailable("its ${_fc_pf_step} failed (${_fc_pf_rc}), see ${_fc_pf_log}")
      return()
    endif()
  endforeach()
  file(REMOVE_RECURSE "${_fc_pf_root}/src" "${_fc_pf_root}/build")
  file(WRITE "${_fc_pf_stamp}" "pFUnit ${FETICONTACT_PFUNIT_VERSION} from ${_fc_pf_archive}\n")
  message(STATUS "pFUnit: built and installed into ${_fc_pf_prefix}")
endif()
file(LOCK "${_fc_pf_root}/.lock" RELEASE)

find_package(PFUNIT REQUIRED PATHS "${_fc_pf_prefix}" NO_DEFAULT_PATH)
set(FETICONTACT_PFUNIT_AVAILABLE ON)
