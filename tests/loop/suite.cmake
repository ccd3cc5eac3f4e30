# Online loop-closure detection (core LoopDetector) on simulated loops and on hku-loop1, and
# segmatch-loop's scoring.
# The simulated loop, the simulated closed route and the hku runs are expensive fixtures: each
# suite runs as one ctest entry so they are built once.
segmatch_test_suite(test_loop loop segmatch_core segmatch_sim segmatch_io nlohmann_json::nlohmann_json
                    WHOLE_SUITES SimulatedLoop ClosedRoute HkuLoop)
target_sources(test_loop PRIVATE ${PROJECT_SOURCE_DIR}/loop/src/loop_eval.cpp)
target_include_directories(test_loop PRIVATE ${PROJECT_SOURCE_DIR}/loop/src)
# The CLI tests run the built tool.
add_dependencies(test_loop segmatch-loop segmatch-sim segmatch-mapbuilder segmatch-mapinfo)
