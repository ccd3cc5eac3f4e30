# Every suite shares one simulated world and map (server_test_util.h, built on first use): one
# ctest entry per suite builds it three times instead of once per test.
segmatch_test_suite(test_server server segmatch_server segmatch_api segmatch_sim segmatch_storage segmatch_io
                    WHOLE_SUITES ServerLocalization ServerRobustness ServerTracking)
