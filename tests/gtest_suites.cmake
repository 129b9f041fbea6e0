# Run by the build after each test executable is linked (tests/CMakeLists.txt,
# carmba_add_test_suites): lists the executable's GoogleTest suites and writes them to OUT as
#   set(carmba_suites "Suite1;Prefix/Suite2;...")
# which the ctest include file of the executable turns into one ctest test per suite.
# -D EXE=<test executable> -D OUT=<file to write>
execute_process(COMMAND "${EXE}" --gtest_list_tests
                OUTPUT_VARIABLE listing RESULT_VARIABLE rc TIMEOUT 60)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "${EXE} --gtest_list_tests failed (${rc}):\n${listing}")
endif()
string(REPLACE "\n" ";" lines "${listing}")
set(suites)
foreach(line IN LISTS lines)
  # A suite line starts in column 0 and ends with '.' (a typed suite adds "  # TypeParam = ...").
  if(line MATCHES "^([^ #][^ ]*)\\.( .*)?$")
    set(suite "${CMAKE_MATCH_1}")
    if(NOT suite MATCHES "^DISABLED_" AND NOT suite MATCHES "/DISABLED_")
      list(APPEND suites "${suite}")
    endif()
  endif()
endforeach()
if(NOT suites)
  message(FATAL_ERROR "${EXE} lists no test suites")
endif()
file(WRITE "${OUT}.new" "set(carmba_suites \"${suites}\")\n")
file(RENAME "${OUT}.new" "${OUT}")
