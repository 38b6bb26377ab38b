# The Debian package (`make package`, docs/PACKAGING.md): rcand, rcan, the gRPC module, man
# pages generated from the --help texts (help2man), bash completion, the systemd unit, the
# examples and the documentation; maintainer scripts in packaging/debian. CPack's DEB generator.

include(GNUInstallDirs)

if(NOT RCAN_SANITIZE AND NOT RCAN_TSAN AND NOT RCAN_FUZZ)
  find_program(RCAN_HELP2MAN help2man)
  set(RCAN_GEN ${PROJECT_BINARY_DIR}/generated/package)
  set(RCAN_PACKAGE_FILES "")
  if(RCAN_HELP2MAN)
    foreach(tool rcand rcan rcan-registry)
      set(target ${tool})
      set(what "the RCAN robot node")
      if(tool STREQUAL "rcan")
        set(target rcan_cli)
        set(what "the RCAN command-line tool")
      elseif(tool STREQUAL "rcan-registry")
        set(what "an RCAN robot registry")
      endif()
      set(program $<TARGET_FILE:${target}>)
      if(CMAKE_CROSSCOMPILING_EMULATOR)
        # A cross build (docs/ARM64.md): help2man runs the program through the emulator, by
        # a wrapper of the program's own name (help2man names the page after it).
        set(program ${RCAN_GEN}/emulated/${tool})
        list(JOIN CMAKE_CROSSCOMPILING_EMULATOR " " emulator)
        file(GENERATE OUTPUT ${program}
          CONTENT "#!/bin/sh\nexec ${emulator} $<TARGET_FILE:${target}> \"$@\"\n"
          FILE_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE)
      endif()
      add_custom_command(OUTPUT ${RCAN_GEN}/${tool}.1.gz
        COMMAND ${CMAKE_COMMAND} -E make_directory ${RCAN_GEN}
        COMMAND ${RCAN_HELP2MAN} --no-info --no-discard-stderr --locale C.UTF-8 --section 1 --name ${what}
                --output ${RCAN_GEN}/${tool}.1 ${program}
        COMMAND gzip -9nf ${RCAN_GEN}/${tool}.1
        DEPENDS ${target}
        COMMENT "man page: ${tool}(1)")
      list(APPEND RCAN_PACKAGE_FILES ${RCAN_GEN}/${tool}.1.gz)
      install(FILES ${RCAN_GEN}/${tool}.1.gz DESTINATION ${CMAKE_INSTALL_MANDIR}/man1)
    endforeach()
  else()
    message(STATUS "help2man not found: no man pages (scripts/install-deps.sh installs it)")
  endif()
  add_custom_command(OUTPUT ${RCAN_GEN}/rcan.bash-completion
    COMMAND ${CMAKE_COMMAND} -E make_directory ${RCAN_GEN}
    # The target's name, not its file: a cross build runs it through the emulator.
    COMMAND rcan_cli completion bash > ${RCAN_GEN}/rcan.bash-completion
    DEPENDS rcan_cli
    COMMENT "bash completion: rcan")
  list(APPEND RCAN_PACKAGE_FILES ${RCAN_GEN}/rcan.bash-completion)
  add_custom_target(rcan_package_files ALL DEPENDS ${RCAN_PACKAGE_FILES})

  install(TARGETS rcan_cli rcan-registry RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
  install(FILES ${RCAN_GEN}/rcan.bash-completion
          DESTINATION ${CMAKE_INSTALL_DATADIR}/bash-completion/completions RENAME rcan)
  install(FILES ${PROJECT_SOURCE_DIR}/packaging/systemd/rcand.service
                ${PROJECT_SOURCE_DIR}/packaging/systemd/rcan-registry.service
          DESTINATION lib/systemd/system)
  install(FILES ${PROJECT_SOURCE_DIR}/examples/sim-robot.rcan.yaml
          DESTINATION ${CMAKE_INSTALL_DOCDIR}/examples)
  # The reference driver process (docs/DRIVERS.md), where `rcand init --driver process` points.
  install(PROGRAMS ${PROJECT_SOURCE_DIR}/examples/drivers/serial_diffbase.py
          DESTINATION ${CMAKE_INSTALL_DATADIR}/rcan/examples/drivers)
  install(FILES ${PROJECT_SOURCE_DIR}/README.md ${PROJECT_SOURCE_DIR}/docs/NODE.md
                ${PROJECT_SOURCE_DIR}/docs/CONFIG.md ${PROJECT_SOURCE_DIR}/docs/PACKAGING.md
                ${PROJECT_SOURCE_DIR}/docs/SECURITY.md ${PROJECT_SOURCE_DIR}/docs/REGISTRY.md
          DESTINATION ${CMAKE_INSTALL_DOCDIR})
endif()

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME rcan)
set(CPACK_PACKAGE_VENDOR "rcan")
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "RCAN robot node (rcand), command-line tool (rcan) and registry (rcan-registry)")
set(CPACK_PACKAGE_DESCRIPTION
  "The Robot Communication & Addressing Network protocol in C++: rcand serves a robot over\nHTTP, WebSocket, gRPC, UDP and MQTT behind a safety core, with an HMAC-chained audit log;\nrcan drives robots and fleets from the command line; rcan-registry registers and resolves\nrobots (not enabled by default).")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_MAINTAINER "rcan maintainers <maintainers@rcan.invalid>")
set(CPACK_DEBIAN_PACKAGE_SECTION misc)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_DEPENDS "adduser")
if(CMAKE_CROSSCOMPILING AND CMAKE_SYSTEM_PROCESSOR STREQUAL "aarch64")
  # The arm64 package (make package-arm64, docs/ARM64.md): dpkg-shlibdeps knows only the
  # machine's installed packages, so the Depends come from the sysroot's packages
  # (cmake/cpack_arm64_depends.cmake).
  set(CPACK_DEBIAN_PACKAGE_ARCHITECTURE arm64)
  set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS OFF)
  set(CPACK_PROJECT_CONFIG_FILE ${PROJECT_BINARY_DIR}/generated/cpack_arm64.cmake)
  file(GENERATE OUTPUT ${CPACK_PROJECT_CONFIG_FILE} CONTENT
"set(RCAN_PACKAGE_ELFS \"$<TARGET_FILE:rcand>;$<TARGET_FILE:rcan_cli>;$<TARGET_FILE:rcan-registry>;$<TARGET_FILE:rcand_grpc>\")
set(RCAN_SYSROOT_LIBDEPS \"${CMAKE_SYSROOT}/.libdeps\")
include(\"${PROJECT_SOURCE_DIR}/cmake/cpack_arm64_depends.cmake\")
")
endif()
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "avahi-daemon")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
  ${PROJECT_SOURCE_DIR}/packaging/debian/postinst
  ${PROJECT_SOURCE_DIR}/packaging/debian/prerm
  ${PROJECT_SOURCE_DIR}/packaging/debian/postrm)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION TRUE)
set(CPACK_STRIP_FILES TRUE)
set(CPACK_PACKAGE_DIRECTORY ${PROJECT_BINARY_DIR}/package)
# The package's files are the rules above and rcand's (the default component, Unspecified);
# librcan's headers and archive (component devel, cmake/RcanInstall.cmake) are not in it.
set(CPACK_INSTALL_CMAKE_PROJECTS "${PROJECT_BINARY_DIR};${PROJECT_NAME};Unspecified;/")
include(CPack)
