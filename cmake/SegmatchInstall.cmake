# `cmake --install` and `cpack -G DEB` (docs/integration.md). Two components:
#   runtime  the tools, the shipped models (share/segmatch/models, found by the tools relative to
#            their own folder), the docs, the systemd unit and the HAProxy files;
#   dev      the libraries segmatch::core, io, storage and api (static), their headers and the
#            CMake package (find_package(segmatch)).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(SEGMATCH_TOOLS segmatch-mapbuilder segmatch-mapinfo segmatch-server segmatch-query segmatch-eval segmatch-train
                   segmatch-loop segmatch-sim)
foreach(tool ${SEGMATCH_TOOLS})
  if(TARGET ${tool})
    install(TARGETS ${tool} RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT runtime)
  endif()
endforeach()
install(DIRECTORY ${PROJECT_SOURCE_DIR}/maps/models/ DESTINATION ${CMAKE_INSTALL_DATADIR}/segmatch/models
        COMPONENT runtime FILES_MATCHING PATTERN "*.yml")
# The README and the manual as they sit in the repository, so that the README's links resolve.
install(FILES ${PROJECT_SOURCE_DIR}/README.md ${PROJECT_SOURCE_DIR}/LICENSE ${PROJECT_SOURCE_DIR}/NOTICE
        DESTINATION ${CMAKE_INSTALL_DOCDIR} COMPONENT runtime)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}/docs COMPONENT runtime
        FILES_MATCHING PATTERN "*.md" PATTERN "*.png")
install(FILES ${PROJECT_SOURCE_DIR}/deploy/systemd/segmatch-server@.service DESTINATION lib/systemd/system COMPONENT runtime)
install(FILES ${PROJECT_SOURCE_DIR}/deploy/systemd/segmatch-server.env ${PROJECT_SOURCE_DIR}/deploy/haproxy/haproxy.cfg
              ${PROJECT_SOURCE_DIR}/deploy/kubernetes/segmatch.yaml
        DESTINATION ${CMAKE_INSTALL_DATADIR}/segmatch/deploy COMPONENT runtime)
install(PROGRAMS ${PROJECT_SOURCE_DIR}/deploy/haproxy/hello-hex.sh DESTINATION ${CMAKE_INSTALL_DATADIR}/segmatch/deploy
        COMPONENT runtime)

# The libraries a C++ project builds on, exported as segmatch::<name>.
set(SEGMATCH_EXPORTED core io storage api)
foreach(name ${SEGMATCH_EXPORTED})
  set_target_properties(segmatch_${name} PROPERTIES EXPORT_NAME ${name})
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${name}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} COMPONENT dev)
endforeach()
install(TARGETS segmatch_core segmatch_io segmatch_storage segmatch_api EXPORT segmatchTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT dev
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
set(SEGMATCH_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/segmatch)
install(EXPORT segmatchTargets NAMESPACE segmatch:: DESTINATION ${SEGMATCH_CMAKE_DIR} COMPONENT dev)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/segmatchConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/segmatchConfig.cmake INSTALL_DESTINATION ${SEGMATCH_CMAKE_DIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/segmatchConfigVersion.cmake COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/segmatchConfig.cmake ${PROJECT_BINARY_DIR}/segmatchConfigVersion.cmake
        DESTINATION ${SEGMATCH_CMAKE_DIR} COMPONENT dev)

# Debian packages: `cd build && cpack -G DEB` -> segmatch_VERSION_ARCH.deb and segmatch-dev_...
set(CPACK_PACKAGE_NAME segmatch)
set(CPACK_PACKAGE_VENDOR "segmatch")
set(CPACK_PACKAGE_CONTACT "segmatch maintainers <segmatch@example.com>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "LiDAR place recognition and localization against a prior map (SegMatch)")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_COMPONENTS_ALL runtime dev)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_RUNTIME_PACKAGE_NAME segmatch)
set(CPACK_DEBIAN_RUNTIME_PACKAGE_SHLIBDEPS ON)  # the shared libraries the tools really link
set(CPACK_DEBIAN_DEV_PACKAGE_NAME segmatch-dev)
set(CPACK_DEBIAN_DEV_PACKAGE_SECTION libdevel)
# Headers need Eigen; the static libraries also link what they use privately (OpenCV's random
# forest, FLANN, SQLite, zstd, lz4), so a consumer's link finds them.
set(CPACK_DEBIAN_DEV_PACKAGE_DEPENDS
    "segmatch (= ${PROJECT_VERSION}), libeigen3-dev, libopencv-dev, libflann-dev, libsqlite3-dev, libzstd-dev, liblz4-dev, pkg-config, nlohmann-json3-dev")
set(CPACK_COMPONENT_RUNTIME_DESCRIPTION "segmatch tools: map builder, localization server, client, evaluation")
set(CPACK_COMPONENT_DEV_DESCRIPTION "segmatch C++ libraries, headers and CMake package")
include(CPack)

# The installed product as a user gets it: install, a consumer project, the two packages.
if(SEGMATCH_BUILD_TESTS)
  add_test(NAME InstallAndPackage COMMAND bash ${PROJECT_SOURCE_DIR}/tests/install/run.sh ${PROJECT_BINARY_DIR} ${PROJECT_SOURCE_DIR})
  # Slow (~17 s): labelled and costed like the slow entries of tests/CMakeLists.txt.
  set_tests_properties(InstallAndPackage PROPERTIES LABELS "install;slow" COST 17 TIMEOUT 900)
endif()
