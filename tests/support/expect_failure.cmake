# ctest helper: runs COMMAND (a ;-list) and passes only if it exits non-zero
# and its output matches EXPECT (a regular expression), i.e. bad input is
# refused with the message a user needs.
#   cmake -DCOMMAND="prog;arg1;arg2" -DEXPECT="regex" -P expect_failure.cmake
execute_process(COMMAND ${COMMAND} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(rc EQUAL 0)
  message(FATAL_ERROR "expected a failure, but '${COMMAND}' exited 0:\n${out}${err}")
endif()
if(NOT "${out}${err}" MATCHES "${EXPECT}")
  message(FATAL_ERROR "'${COMMAND}' failed as expected (${rc}) but its output does not match '${EXPECT}':\n${out}${err}")
endif()
