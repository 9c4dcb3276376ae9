# add_unit_test(<name> SOURCES <files> [LIBS <targets>] [RANKS <n>...] [ARGS <args>] [TIMEOUT <s>]
#               [LABELS <labels>])
# Builds one test program and registers one CTest test per rank count,
# named <name>_np<n>, run as `mpiexec -n <n> <program> <args>`. A program
# whose every check was skipped exits 77, which CTest reports as skipped.
# More ranks than cores are allowed (oversubscription); root is allowed.

set(FETICONTACT_MPIEXEC ${MPIEXEC_EXECUTABLE} --oversubscribe --bind-to none)
set(FETICONTACT_TEST_ENV
    "OMPI_ALLOW_RUN_AS_ROOT=1;OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1;OMPI_MCA_rmaps_base_oversubscribe=1;OMPI_MCA_btl_vader_single_copy_mechanism=none;OPENBLAS_NUM_THREADS=1;OMP_NUM_THREADS=1")

function(add_unit_test name)
  cmake_parse_arguments(T "" "TIMEOUT" "SOURCES;LIBS;RANKS;ARGS;LABELS" ${ARGN})
  if(NOT T_RANKS)
    set(T_RANKS 1)
  endif()
  if(NOT T_TIMEOUT)
    set(T_TIMEOUT 300)
  endif()
  add_executable(${name} ${T_SOURCES})
  target_link_libraries(${name} PRIVATE fc_testing ${T_LIBS})
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/tests/bin)
  set_source_files_properties(${T_SOURCES} PROPERTIES Fortran_PREPROCESS ON)
  target_compile_options(${name} PRIVATE -ffree-line-length-none)
  foreach(np ${T_RANKS})
    add_test(NAME ${name}_np${np}
             COMMAND ${FETICONTACT_MPIEXEC} -n ${np} $<TARGET_FILE:${name}> ${T_ARGS}
             WORKING_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR})
    set_tests_properties(${name}_np${np} PROPERTIES
      TIMEOUT ${T_TIMEOUT} PROCESSORS ${np} ENVIRONMENT "${FETICONTACT_TEST_ENV}"
      LABELS "${T_LABELS}" SKIP_RETURN_CODE 77)
  endforeach()
endfunction()

# add_program_test(<name> INPUT <file.nml> RANKS <n> [ARGS <args>] [EXPECT_FAIL <regex>]
#                  [EXPECT_OUTPUT <regex>] [TIMEOUT <s>])
# Runs the real feticontact executable on <file.nml>. With EXPECT_FAIL the run
# must exit non-zero and its output must match <regex>; otherwise it must exit
# 0 (and match EXPECT_OUTPUT when given).
function(add_program_test name)
  cmake_parse_arguments(T "" "INPUT;EXPECT_FAIL;EXPECT_OUTPUT;TIMEOUT" "RANKS;ARGS;LABELS" ${ARGN})
  if(NOT T_TIMEOUT)
    set(T_TIMEOUT 120)
  endif()
  foreach(np ${T_RANKS})
    add_test(NAME ${name}_np${np}
      COMMAND ${CMAKE_COMMAND}
        "-DMPIEXEC=${MPIEXEC_EXECUTABLE}" "-DNP=${np}" "-DPROGRAM=$<TARGET_FILE:feticontact>"
        "-DINPUT=${T_INPUT}" "-DARGS=${T_ARGS}" "-DEXPECT_FAIL=${T_EXPECT_FAIL}"
        "-DEXPECT_OUTPUT=${T_EXPECT_OUTPUT}" "-DTIMEOUT=${T_TIMEOUT}"
        -P ${PROJECT_SOURCE_DIR}/cmake/RunProgramTest.cmake
      WORKING_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR})
    math(EXPR outer "${T_TIMEOUT} + 30")
    set_tests_properties(${name}_np${np} PROPERTIES
      TIMEOUT ${outer} PROCESSORS ${np} ENVIRONMENT "${FETICONTACT_TEST_ENV}" LABELS "${T_LABELS}")
  endforeach()
endfunction()
