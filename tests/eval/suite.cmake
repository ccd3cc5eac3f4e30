segmatch_test_suite(test_eval eval segmatch_eval segmatch_server segmatch_storage segmatch_sim segmatch_io segmatch_core WHOLE_SUITES RegressionMap)
target_link_libraries(test_eval PRIVATE nlohmann_json::nlohmann_json)
target_compile_definitions(test_eval PRIVATE SEGMATCH_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
# The real-recording tests run the built tools.
add_dependencies(test_eval segmatch-mapbuilder segmatch-eval)
