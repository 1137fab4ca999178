# CMake toolchain file for Debian's arm-none-eabi-gcc (12.2, newlib), bare-metal Cortex-M:
#
#   cmake -S firmware_ref/mcu -B firmware_ref/build-mcu-m4 \
#         -DCMAKE_TOOLCHAIN_FILE=firmware_ref/mcu/toolchain-arm-none-eabi.cmake -DFWREF_CPU=cortex-m4 ...
#
# FWREF_CPU: cortex-m4 (Cortex-M4F: single-precision FPv4, hard-float ABI) or cortex-m7 (FPv5 with
# double precision, hard-float ABI).
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)
set(CMAKE_C_COMPILER arm-none-eabi-gcc)
set(CMAKE_CXX_COMPILER arm-none-eabi-g++)
set(CMAKE_ASM_COMPILER arm-none-eabi-gcc)
set(CMAKE_AR arm-none-eabi-ar)
set(CMAKE_OBJCOPY arm-none-eabi-objcopy)
set(CMAKE_SIZE arm-none-eabi-size)
# try_compile builds a static library: a bare-metal executable needs our startup and linker script.
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)

set(FWREF_CPU "cortex-m4" CACHE STRING "Target core: cortex-m4 or cortex-m7")
set_property(CACHE FWREF_CPU PROPERTY STRINGS cortex-m4 cortex-m7)
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES FWREF_CPU)
if(FWREF_CPU STREQUAL "cortex-m4")
  set(FWREF_CPU_FLAGS "-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard")
elseif(FWREF_CPU STREQUAL "cortex-m7")
  set(FWREF_CPU_FLAGS "-mcpu=cortex-m7 -mthumb -mfpu=fpv5-d16 -mfloat-abi=hard")
else()
  message(FATAL_ERROR "FWREF_CPU must be cortex-m4 or cortex-m7, found '${FWREF_CPU}'")
endif()

set(CMAKE_C_FLAGS_INIT "${FWREF_CPU_FLAGS}")
set(CMAKE_CXX_FLAGS_INIT "${FWREF_CPU_FLAGS}")
set(CMAKE_ASM_FLAGS_INIT "${FWREF_CPU_FLAGS}")
set(CMAKE_EXE_LINKER_FLAGS_INIT "${FWREF_CPU_FLAGS}")

# Host programs (python, qemu) from the host; nothing else is searched for in a sysroot.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
