# Every suite shares one simulated world and map (server_test_util.h, built on first use): one
# ctest entry per suite builds it once per suite instead of once per test.
segmatch_test_suite(test_server server segmatch_server segmatch_api segmatch_vehicle segmatch_sim segmatch_storage
                    segmatch_io WHOLE_SUITES ServerLocalization ServerRobustness ServerTracking ServerSegments)
