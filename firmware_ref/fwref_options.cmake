# firmware_ref/fwref_options.cmake -- scope: what the host build (CMakeLists.txt) and the Cortex-M build
# (mcu/CMakeLists.txt) share: their build options reach the code as compile definitions of the same name.

# Each option named in ARGN that is ON becomes a compile definition of the same name on the INTERFACE
# library ``target`` (the options that every translation unit of that build sees).
function(fwref_option_definitions target)
  foreach(opt IN LISTS ARGN)
    if(${opt})
      target_compile_definitions(${target} INTERFACE ${opt})
    endif()
  endforeach()
endfunction()
