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
