# Helpers shared by every module: one folder = one library target, tests beside the code.

set(INSTASCENE_WARNINGS -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor -Wno-missing-field-initializers)
if(INSTASCENE_WERROR)
  list(APPEND INSTASCENE_WARNINGS -Werror)
endif()

# No FMA contraction: results must not depend on how the compiler fuses multiply-adds.
set(INSTASCENE_OPT_FLAGS -ffp-contract=off)
if(INSTASCENE_ARCH)
  # Fall back to the compiler default on CPUs without AVX2 (checked on the build machine).
  file(READ /proc/cpuinfo _cpuinfo LIMIT 65536)
  if(NOT INSTASCENE_ARCH STREQUAL "x86-64-v3" OR _cpuinfo MATCHES "avx2")
    list(APPEND INSTASCENE_OPT_FLAGS -march=${INSTASCENE_ARCH})
  endif()
endif()

if(INSTASCENE_FUZZ)
  add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer
                      -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
endif()
if(INSTASCENE_SANITIZE)
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
endif()

# Project-code compile settings (warnings as errors, arch flags); third-party code is not affected.
function(instascene_target_settings target)
  target_compile_options(${target} PRIVATE ${INSTASCENE_WARNINGS} ${INSTASCENE_OPT_FLAGS})
  target_include_directories(${target} PUBLIC ${PROJECT_SOURCE_DIR})
endfunction()

# instascene_library(NAME SRCS a.cc b.cc DEPS x y)
function(instascene_library name)
  cmake_parse_arguments(ARG "" "" "SRCS;DEPS" ${ARGN})
  add_library(${name} STATIC ${ARG_SRCS})
  instascene_target_settings(${name})
  target_link_libraries(${name} PUBLIC ${ARG_DEPS})
endfunction()

# instascene_test(NAME SRCS a_test.cc DEPS x y): a GoogleTest binary registered with ctest.
function(instascene_test name)
  cmake_parse_arguments(ARG "" "" "SRCS;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SRCS})
  instascene_target_settings(${name})
  target_compile_definitions(${name} PRIVATE INSTASCENE_SHARED_DIR="${INSTASCENE_SHARED_DIR}")
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES LABELS unit)
endfunction()

# instascene_benchmark(NAME SRCS a_benchmark.cc DEPS x y): a Google Benchmark binary (make bench).
function(instascene_benchmark name)
  if(NOT INSTASCENE_BUILD_BENCHMARKS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "" "SRCS;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SRCS})
  instascene_target_settings(${name})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} benchmark::benchmark)
  set_property(GLOBAL APPEND PROPERTY INSTASCENE_BENCHMARKS ${name})
endfunction()
