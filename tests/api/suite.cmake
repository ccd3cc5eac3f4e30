segmatch_test_suite(test_api api segmatch_api)
target_compile_definitions(test_api PRIVATE SEGMATCH_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
