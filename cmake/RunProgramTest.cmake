# Run by add_program_test: run feticontact under mpiexec and judge its exit
# status and output. A run that does not end within TIMEOUT seconds fails
# (this is how a hang of any rank is caught). With EXPECT_FAIL the status must
# be non-zero (and equal EXPECT_STATUS when given) and the output must match.
# With DIRECT and NP 1 the program starts without mpiexec (an MPI singleton: the same program on
# one rank, without the launcher's start-up, which costs more than a run that stops at its input).
separate_arguments(args UNIX_COMMAND "${ARGS}")
if(DIRECT AND NP EQUAL 1)
  set(launch ${PROGRAM})
else()
  set(launch ${MPIEXEC} --oversubscribe --bind-to none -n ${NP} ${PROGRAM})
endif()
execute_process(
  COMMAND ${launch} ${args} ${INPUT}
  RESULT_VARIABLE status OUTPUT_VARIABLE out ERROR_VARIABLE err TIMEOUT ${TIMEOUT})
set(all "${out}\n${err}")
message("exit status: ${status}\n--- output ---\n${all}")
if(status MATCHES "timeout|Process terminated")
  message(FATAL_ERROR "the run did not end within ${TIMEOUT} s (a hang?)")
endif()
if(EXPECT_FAIL)
  if(status EQUAL 0)
    message(FATAL_ERROR "expected a non-zero exit status, got 0")
  endif()
  if(EXPECT_STATUS AND NOT status EQUAL EXPECT_STATUS)
    message(FATAL_ERROR "expected exit status ${EXPECT_STATUS}, got ${status}")
  endif()
  string(REGEX MATCH "${EXPECT_FAIL}" found "${all}")
  if(NOT found)
    message(FATAL_ERROR "the output does not match the expected message: ${EXPECT_FAIL}")
  endif()
else()
  if(NOT status EQUAL 0)
    message(FATAL_ERROR "expected exit status 0, got ${status}")
  endif()
  if(EXPECT_OUTPUT)
    string(REGEX MATCH "${EXPECT_OUTPUT}" found "${all}")
    if(NOT found)
      message(FATAL_ERROR "the output does not match: ${EXPECT_OUTPUT}")
    endif()
  endif()
endif()
