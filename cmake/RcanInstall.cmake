# librcan for other programs (docs/ARCHITECTURE.md): `cmake --install <tree> --component devel`
# puts the public headers (include/rcan, without the client library's client.h), librcan.a and
# librcan_base.a,
# the CMake package (find_package(rcan CONFIG): the imported target rcan::rcan, which brings
# OpenSSL's libcrypto, threads and C++20) and rcan.pc (pkg-config) under the prefix.
#
# These rules are the component "devel"; the Debian package holds the programs only: cpack
# installs the component the package's own rules are in (Unspecified, cmake/RcanPackage.cmake).
include(CMakePackageConfigHelpers)

set(RCAN_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/rcan)
# librcan_base.a is base (src/base: clocks, the file-system Env), which librcan stands on.
install(TARGETS rcan rcan_base EXPORT rcanTargets ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT devel)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/include/rcan DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        COMPONENT devel FILES_MATCHING PATTERN "*.h" PATTERN "client.h" EXCLUDE)
install(EXPORT rcanTargets NAMESPACE rcan:: DESTINATION ${RCAN_CMAKE_DIR} COMPONENT devel)

configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/rcanConfig.cmake.in
  ${PROJECT_BINARY_DIR}/generated/rcanConfig.cmake INSTALL_DESTINATION ${RCAN_CMAKE_DIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/generated/rcanConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/generated/rcanConfig.cmake
              ${PROJECT_BINARY_DIR}/generated/rcanConfigVersion.cmake
        DESTINATION ${RCAN_CMAKE_DIR} COMPONENT devel)

# rcan.pc finds its prefix from where it is installed (${pcfiledir}), so the copy works under
# any --prefix.
file(RELATIVE_PATH RCAN_PC_UP /prefix/${CMAKE_INSTALL_LIBDIR}/pkgconfig /prefix)
configure_file(${PROJECT_SOURCE_DIR}/cmake/rcan.pc.in ${PROJECT_BINARY_DIR}/generated/rcan.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/generated/rcan.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig
        COMPONENT devel)

# tests/install: installs the component into a temporary prefix and builds a program against it,
# with find_package and with pkg-config (the release tree only: a sanitizer's librcan.a needs
# its runtime).
if(RCAN_BUILD_TESTS AND NOT RCAN_SANITIZE AND NOT RCAN_TSAN AND NOT RCAN_FUZZ AND NOT CMAKE_CROSSCOMPILING)
  add_test(NAME install.librcan_consumer
           COMMAND bash ${PROJECT_SOURCE_DIR}/tests/install/consumer_test.sh ${PROJECT_BINARY_DIR}
                   ${PROJECT_SOURCE_DIR}/tests/install/consumer)
  set_tests_properties(install.librcan_consumer PROPERTIES TIMEOUT 300 LABELS install)
endif()
