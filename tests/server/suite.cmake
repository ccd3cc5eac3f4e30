# Every server suite (and Deploy) shares one simulated world and map (server_world.h), built once
# per build by make_server_world into the fixture cache; the ServerWorld entry builds it, the
# other entries run after it. The slow suites each run as one entry (one process).
add_executable(make_server_world ${CMAKE_CURRENT_LIST_DIR}/../fixtures/make_server_world.cpp)
target_link_libraries(make_server_world PRIVATE segmatch_api segmatch_sim segmatch_storage segmatch_io)
target_include_directories(make_server_world PRIVATE ${CMAKE_CURRENT_SOURCE_DIR})
set_target_properties(make_server_world PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/tests)
segmatch_test_suite(test_server server segmatch_server segmatch_api segmatch_vehicle segmatch_sim segmatch_storage
                    segmatch_io ${OpenCV_LIBS} nlohmann_json::nlohmann_json
                    WHOLE_SUITES ServerWorld ServerLocalization ServerRobustness ServerTracking ServerSegments ServerConsole
                    FIXTURE server_world FIXTURE_SETUP ServerWorld)
add_dependencies(test_server make_server_world)
