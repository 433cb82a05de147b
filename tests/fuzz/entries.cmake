# fusion::fuzz_entries: the bodies of the fuzz targets, plain C++, built in every build (the
# replay of tests/fuzz/regressions links them; tests/unit/fuzz).
#
# The fuzz build (FUSION_BUILD_FUZZERS) compiles only the service sources the entries reach
# instead of all of fusion::service: fusiond's gRPC server alone takes ~80 s to compile under
# the sanitizers. An undefined reference here means an entry reached another service source.
if(FUSION_BUILD_FUZZERS)
  add_library(fusion_fuzz_service STATIC
    ${PROJECT_SOURCE_DIR}/service/src/config.cc
    ${PROJECT_SOURCE_DIR}/service/src/conversions.cc
    ${PROJECT_SOURCE_DIR}/service/src/persistence.cc
    ${PROJECT_SOURCE_DIR}/service/src/ros2_config.cc
    ${PROJECT_SOURCE_DIR}/service/src/security.cc
    ${PROJECT_SOURCE_DIR}/service/src/validation.cc)
  target_include_directories(fusion_fuzz_service PUBLIC ${PROJECT_SOURCE_DIR}/service/include)
  target_link_libraries(fusion_fuzz_service PUBLIC fusion::core fusion::proto fusion::idl
    gRPC::grpc++)
  set(fusion_fuzz_service_lib fusion_fuzz_service)
else()
  set(fusion_fuzz_service_lib fusion::service)
endif()

file(GLOB fuzz_entry_sources CONFIGURE_DEPENDS ${CMAKE_CURRENT_LIST_DIR}/entries/*.cc)
add_library(fusion_fuzz_entries STATIC ${fuzz_entry_sources})
add_library(fusion::fuzz_entries ALIAS fusion_fuzz_entries)
target_include_directories(fusion_fuzz_entries PUBLIC ${CMAKE_CURRENT_LIST_DIR})
target_link_libraries(fusion_fuzz_entries
  PUBLIC ${fusion_fuzz_service_lib} fusion::clients_common fusion::ros2_wire
  PRIVATE fusion::warnings)

# Where the replay test (tests/unit/fuzz/fuzz_regressions_test.cc) finds the inputs.
target_compile_definitions(fusion_fuzz_entries PUBLIC
  FUSION_FUZZ_REGRESSIONS_DIR="${CMAKE_CURRENT_LIST_DIR}/regressions")
