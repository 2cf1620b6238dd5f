# CMake toolchain file for cross builds of KinDynGen's C for Cortex-M with arm-none-eabi-gcc.
#   cmake -S generated_float/lwr4/c -B build-m4f -DCMAKE_TOOLCHAIN_FILE=path/to/arm-none-eabi.cmake
#   cmake -S generated/lwr4/c -B build-m7 -DCMAKE_TOOLCHAIN_FILE=path/to/arm-none-eabi.cmake -DKDG_CPU=m7
# Leave CMAKE_BUILD_TYPE empty: its Release flags (-O3) would override the -O2 here.
# KDG_CPU=m4f (default: Cortex-M4F, single-precision FPU: generate with --scalar float) or
# m7 (Cortex-M7, double-precision FPU: either scalar). The flags are those of the measured
# figures (docs/embedded.md); -fno-schedule-insns keeps gcc's pre-register-allocation
# scheduling from raising the stack of the largest functions (lwr4 Y_m on M7: 5064 -> 1984 B).
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)
set(CMAKE_C_COMPILER arm-none-eabi-gcc)
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)   # no startup code needed to test the compiler
set(KDG_CPU m4f CACHE STRING "m4f (Cortex-M4F) or m7 (Cortex-M7)")
if(KDG_CPU STREQUAL "m7")
  set(KDG_CPU_FLAGS "-mcpu=cortex-m7 -mthumb -mfloat-abi=hard -mfpu=fpv5-d16")
else()
  set(KDG_CPU_FLAGS "-mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16")
endif()
# -ffp-contract=off: no fused multiply-adds (the M4F and M7 FPUs have them), the results of strict
# C99 on the host, bit for bit; the library's CMakeLists.txt sets it too (and -std=c99), this is
# for the firmware's own files
set(CMAKE_C_FLAGS_INIT "${KDG_CPU_FLAGS} -O2 -ffp-contract=off -ffunction-sections -fdata-sections -fno-schedule-insns")
# no -fPIC on bare metal (the library's CMakeLists.txt turns position-independent code on only
# for hosts; older ones did for every system): emptied after CMake's compiler rules, which set
# it, by this file read as rules override
set(CMAKE_USER_MAKE_RULES_OVERRIDE ${CMAKE_CURRENT_LIST_FILE})
set(CMAKE_C_COMPILE_OPTIONS_PIC "")
set(CMAKE_C_COMPILE_OPTIONS_PIE "")
set(CMAKE_EXE_LINKER_FLAGS_INIT "-Wl,--gc-sections")
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
