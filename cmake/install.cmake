# `cmake --install build --prefix P` (docs/embedding.md): libtissue with its
# headers (tissue/simulation.hpp, tissue/tissue_c.h), the engine's static
# libraries with theirs (under include/tissue/engine, for hosts that drive
# the Scheduler themselves), and the CMake package: find_package(Tissue
# CONFIG [COMPONENTS cuda]) gives Tissue::tissue, Tissue::core, Tissue::cpu,
# Tissue::scene, Tissue::io, Tissue::backends, Tissue::session, Tissue::haptics and, when the build had the
# CUDA backend, Tissue::cuda.
include(CMakePackageConfigHelpers)
set(TISSUE_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/Tissue)
set(TISSUE_ENGINE_INCLUDE ${CMAKE_INSTALL_INCLUDEDIR}/tissue/engine)

set(_tissue_engine tissue_core tissue_cpu tissue_scene tissue_io tissue_backends tissue_session tissue_haptics)
set(_tissue_engine_dirs core cpu scene io backends session haptics)
if(TISSUE_HAVE_CUDA)
  list(APPEND _tissue_engine tissue_cuda)
  list(APPEND _tissue_engine_dirs cuda)
endif()
foreach(t ${_tissue_engine})
  string(REPLACE "tissue_" "" _name ${t})
  set_target_properties(${t} PROPERTIES EXPORT_NAME ${_name})
endforeach()
# The engine's headers include each other as "core/x.hpp": their root.
target_include_directories(tissue_core PUBLIC $<INSTALL_INTERFACE:${TISSUE_ENGINE_INCLUDE}>)

install(TARGETS tissue_api ${_tissue_engine} EXPORT TissueTargets
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}/tissue
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(DIRECTORY api/include/tissue DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
foreach(d ${_tissue_engine_dirs})
  install(DIRECTORY ${d}/ DESTINATION ${TISSUE_ENGINE_INCLUDE}/${d} FILES_MATCHING PATTERN "*.hpp" PATTERN "*.cuh")
endforeach()
install(TARGETS tissue tissue-view RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(EXPORT TissueTargets NAMESPACE Tissue:: DESTINATION ${TISSUE_CMAKE_DIR})

configure_package_config_file(${CMAKE_CURRENT_LIST_DIR}/TissueConfig.cmake.in
  ${CMAKE_CURRENT_BINARY_DIR}/TissueConfig.cmake INSTALL_DESTINATION ${TISSUE_CMAKE_DIR})
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/TissueConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/TissueConfig.cmake ${CMAKE_CURRENT_BINARY_DIR}/TissueConfigVersion.cmake
  DESTINATION ${TISSUE_CMAKE_DIR})
