# Warnings and sanitizer flags shared by every target of the project.
add_library(fusion_warnings INTERFACE)
add_library(fusion::warnings ALIAS fusion_warnings)
target_compile_options(fusion_warnings INTERFACE
  $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wno-unused-parameter>)

if(FUSION_SANITIZER STREQUAL "address")
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
elseif(FUSION_SANITIZER STREQUAL "thread")
  add_compile_options(-fsanitize=thread -fno-omit-frame-pointer)
  add_link_options(-fsanitize=thread)
elseif(NOT FUSION_SANITIZER STREQUAL "")
  message(FATAL_ERROR "FUSION_SANITIZER must be '', 'address' or 'thread', not '${FUSION_SANITIZER}'")
endif()

# libFuzzer targets (tests/fuzz): clang only, on top of FUSION_SANITIZER=address. Every target
# of the build gets libFuzzer's coverage instrumentation; only the fuzz executables link its
# main (-fsanitize=fuzzer). scripts/fuzz.sh configures build-fuzz/ this way.
option(FUSION_BUILD_FUZZERS
  "Build the libFuzzer targets in tests/fuzz (clang, FUSION_SANITIZER=address)" OFF)
if(FUSION_BUILD_FUZZERS)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    message(FATAL_ERROR
      "FUSION_BUILD_FUZZERS needs clang (CC=clang CXX=clang++), not ${CMAKE_CXX_COMPILER_ID}")
  endif()
  if(NOT FUSION_SANITIZER STREQUAL "address")
    message(FATAL_ERROR "FUSION_BUILD_FUZZERS needs -DFUSION_SANITIZER=address")
  endif()
  if(NOT FUSION_BUILD_SERVICE OR NOT FUSION_BUILD_TESTS)
    message(FATAL_ERROR "FUSION_BUILD_FUZZERS needs FUSION_BUILD_SERVICE and FUSION_BUILD_TESTS")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link)
endif()
