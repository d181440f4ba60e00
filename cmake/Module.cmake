# Warnings as errors on our own targets only; third-party headers are SYSTEM includes.
function(ltm_warnings target)
  if(LTM_FUZZ)  # other compiler (clang), other warnings: reported, not fatal, in the fuzz build
    target_compile_options(${target} PRIVATE -Wall -Wextra)
  else()
    target_compile_options(${target} PRIVATE -Wall -Wextra -Werror)
  endif()
endfunction()

# ltm_module(NAME <name> SOURCES ... PUBLIC_DEPS ... PRIVATE_DEPS ...)
# Defines the static library ltm_<name> (alias ltm::<name>) for src/ltmapper/<name>.
function(ltm_module)
  cmake_parse_arguments(M "" "NAME" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(ltm_${M_NAME} STATIC ${M_SOURCES})
  add_library(ltm::${M_NAME} ALIAS ltm_${M_NAME})
  target_include_directories(ltm_${M_NAME} PUBLIC ${PROJECT_SOURCE_DIR}/src)
  target_link_libraries(ltm_${M_NAME} PUBLIC ${M_PUBLIC_DEPS} PRIVATE ${M_PRIVATE_DEPS})
  set_target_properties(ltm_${M_NAME} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  ltm_warnings(ltm_${M_NAME})
  set_property(GLOBAL APPEND PROPERTY LTM_MODULES ltm::${M_NAME})
endfunction()

# ltm_test(<name> SOURCES ... DEPS ...): one GoogleTest executable per module, registered in ctest.
function(ltm_test name)
  cmake_parse_arguments(T "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${T_SOURCES})
  target_link_libraries(${name} PRIVATE ${T_DEPS} GTest::gtest GTest::gtest_main Threads::Threads)
  target_compile_definitions(${name} PRIVATE
    LTM_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    LTM_BINARY_DIR="${PROJECT_BINARY_DIR}"
    LTM_EXE="$<TARGET_FILE:ltmapper>")
  ltm_warnings(${name})
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES ENVIRONMENT "LTM_SOURCE_DIR=${PROJECT_SOURCE_DIR}")
endfunction()

