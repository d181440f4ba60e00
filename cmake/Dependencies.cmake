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
# Reports: Markdown to HTML (libcmark-gfm-dev, libcmark-gfm-extensions-dev: GitHub's tables).
# Debian ships no CMake config or .pc file for the extensions; both are plain libraries.
find_path(CMARK_GFM_INCLUDE_DIR cmark-gfm-core-extensions.h REQUIRED)
find_library(CMARK_GFM_LIBRARY cmark-gfm REQUIRED)
find_library(CMARK_GFM_EXTENSIONS_LIBRARY cmark-gfm-extensions REQUIRED)
if(NOT TARGET ltm_cmark)
  add_library(ltm_cmark INTERFACE)
  target_include_directories(ltm_cmark SYSTEM INTERFACE ${CMARK_GFM_INCLUDE_DIR})
  target_link_libraries(ltm_cmark INTERFACE ${CMARK_GFM_EXTENSIONS_LIBRARY} ${CMARK_GFM_LIBRARY})
endif()

# Heavy libraries: only the .cpp files of the module that owns them include their headers.
find_package(PCL 1.13 REQUIRED COMPONENTS common io kdtree search features)
find_package(Ceres 2.1 REQUIRED)
find_package(embree 3 REQUIRED)

# LZF for binary_compressed PCDs (our own PCD reader and writer, io/pcd.cpp).
find_package(liblzf CONFIG REQUIRED)

# PCL exports plain variables; wrap them in imported targets with SYSTEM includes. ltm_pcl is what
# the program links: PCL's templates compiled into our own code (PCL_NO_PRECOMPILE; the one user is
# slam/global.cpp: normals, kd-tree search and RANSAC; its FPFH is ours), so PCL's libraries of
# precompiled instantiations are not loaded at every start: pcl_io brought VTK (67 shared objects,
# ~50 ms), pcl_features 116 000 symbol relocations (~27 ms). FLANN's headers, compiled with them,
# use LZ4. ltm_pcl_io adds pcl_io for the tests and benches that compare our PCD files with PCL's;
# PCL_FEATURES_LIBRARIES is for the test that compares our FPFH with PCL's.
if(NOT TARGET ltm_pcl)
  pkg_check_modules(LZ4 REQUIRED IMPORTED_TARGET liblz4)
  add_library(ltm_pcl INTERFACE)
  target_include_directories(ltm_pcl SYSTEM INTERFACE ${PCL_INCLUDE_DIRS})
  target_link_libraries(ltm_pcl INTERFACE ${PCL_COMMON_LIBRARIES} PkgConfig::LZ4)
  target_compile_definitions(ltm_pcl INTERFACE ${PCL_DEFINITIONS} PCL_NO_PRECOMPILE)
  add_library(ltm_pcl_io INTERFACE)
  target_link_libraries(ltm_pcl_io INTERFACE ltm_pcl ${PCL_IO_LIBRARIES})
endif()
