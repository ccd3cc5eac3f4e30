# Third-party dependencies, all from Debian packages (scripts/install-deps.sh).
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(Threads REQUIRED)
find_package(OpenCV REQUIRED COMPONENTS core imgproc imgcodecs ml)
find_package(flann REQUIRED)
find_package(CLI11 REQUIRED)
find_package(nlohmann_json 3 REQUIRED)
find_package(SQLite3 REQUIRED)  # segmatch_storage: the map file (SQLite::SQLite3)
if(SEGMATCH_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
if(SEGMATCH_BUILD_BENCH)
  find_package(benchmark QUIET)
  # PCL only for segmatch-bench, which times the stock PCL stages the original SegMatch used
  # against ours. No library links it. VTK is disabled first: PCL's config otherwise drags it
  # in and fails on Debian with "VTK::mpi ... MPI::MPI_C not found".
  set(CMAKE_DISABLE_FIND_PACKAGE_VTK ON)
  find_package(PCL 1.10 REQUIRED COMPONENTS common filters segmentation features kdtree search)
  unset(CMAKE_DISABLE_FIND_PACKAGE_VTK)
endif()
