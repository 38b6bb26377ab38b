# Cross build for arm64 (aarch64) with Debian's cross toolchain (crossbuild-essential-arm64)
# against the sysroot that scripts/arm64-sysroot.sh unpacks (make cross-arm64, docs/ARM64.md).
# The build tools that run during the build (protoc, grpc_cpp_plugin, idlc) are the machine's
# own; libraries, headers, CMake packages and pkg-config files come from the sysroot only.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)

if(NOT RCAN_ARM64_SYSROOT)
  set(RCAN_ARM64_SYSROOT ${CMAKE_CURRENT_LIST_DIR}/../build/arm64-sysroot)
endif()
get_filename_component(RCAN_ARM64_SYSROOT ${RCAN_ARM64_SYSROOT} ABSOLUTE)
if(NOT EXISTS ${RCAN_ARM64_SYSROOT}/usr/include/openssl)
  message(FATAL_ERROR "no arm64 sysroot in ${RCAN_ARM64_SYSROOT}: run scripts/arm64-sysroot.sh")
endif()
set(CMAKE_TRY_COMPILE_PLATFORM_VARIABLES RCAN_ARM64_SYSROOT)
set(CMAKE_SYSROOT ${RCAN_ARM64_SYSROOT})
set(CMAKE_FIND_ROOT_PATH ${RCAN_ARM64_SYSROOT})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)

set(ENV{PKG_CONFIG_SYSROOT_DIR} ${RCAN_ARM64_SYSROOT})
set(ENV{PKG_CONFIG_LIBDIR} "${RCAN_ARM64_SYSROOT}/usr/lib/aarch64-linux-gnu/pkgconfig:${RCAN_ARM64_SYSROOT}/usr/share/pkgconfig")

# Test programs run under qemu-user, which finds the arm64 loader and libraries in the sysroot.
set(CMAKE_CROSSCOMPILING_EMULATOR /usr/bin/qemu-aarch64-static -L ${RCAN_ARM64_SYSROOT})
