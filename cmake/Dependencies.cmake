# Every dependency comes from Debian 12 packages (scripts/install-deps.sh). Nothing is downloaded.
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(TBB REQUIRED)
find_package(nanoflann REQUIRED)
find_package(yaml-cpp REQUIRED)
find_package(CLI11 REQUIRED)
find_package(spdlog REQUIRED)
find_package(PNG REQUIRED)
find_package(SQLite3 REQUIRED)
find_package(Threads REQUIRED)
find_package(PkgConfig REQUIRED)
pkg_check_modules(ZSTD REQUIRED IMPORTED_TARGET libzstd)
# ltmapper view: HTTP server (libcpp-httplib-dev) and JSON (nlohmann-json3-dev).
pkg_check_modules(HTTPLIB REQUIRED IMPORTED_TARGET cpp-httplib)
find_package(nlohmann_json 3 REQUIRED)

# Heavy libraries: only the .cpp files of the module that owns them include their headers.
find_package(PCL 1.13 REQUIRED COMPONENTS common io kdtree search filters features registration segmentation)
find_package(Ceres 2.1 REQUIRED)
find_package(embree 3 REQUIRED)

# LZF for binary_compressed PCDs (our own PCD reader and writer, io/pcd.cpp).
find_package(liblzf CONFIG REQUIRED)

# PCL exports plain variables; wrap them in imported targets with SYSTEM includes. ltm_pcl is what
# the program links: no pcl_io, whose VTK-laden 67 shared objects cost every command's start
# ~75 ms in the dynamic loader. ltm_pcl_io adds it for the tests and benches that compare our
# PCD files with PCL's.
if(NOT TARGET ltm_pcl)
  add_library(ltm_pcl INTERFACE)
  target_include_directories(ltm_pcl SYSTEM INTERFACE ${PCL_INCLUDE_DIRS})
  target_link_libraries(ltm_pcl INTERFACE ${PCL_COMMON_LIBRARIES} ${PCL_KDTREE_LIBRARIES} ${PCL_SEARCH_LIBRARIES}
                        ${PCL_FILTERS_LIBRARIES} ${PCL_FEATURES_LIBRARIES} ${PCL_REGISTRATION_LIBRARIES}
                        ${PCL_SEGMENTATION_LIBRARIES})
  target_compile_definitions(ltm_pcl INTERFACE ${PCL_DEFINITIONS})
  add_library(ltm_pcl_io INTERFACE)
  target_link_libraries(ltm_pcl_io INTERFACE ltm_pcl ${PCL_IO_LIBRARIES})
endif()
