# The stored-map regression, the three real recordings and the tracked kilometre each run as one
# entry (one process):
# the first shares its simulated queries, the second starts early (its COST in
# tests/CMakeLists.txt) instead of finishing the suite alone.
segmatch_test_suite(test_eval eval segmatch_eval segmatch_server segmatch_storage segmatch_sim segmatch_io segmatch_core
                    WHOLE_SUITES RegressionMap Recordings/RealLocalization TrackedDrift)
target_link_libraries(test_eval PRIVATE nlohmann_json::nlohmann_json)
target_compile_definitions(test_eval PRIVATE SEGMATCH_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
# The real-recording and tracked-drift tests run the built tools.
add_dependencies(test_eval segmatch-mapbuilder segmatch-eval segmatch-sim)
