segmatch_test_suite(test_api api segmatch_api)
