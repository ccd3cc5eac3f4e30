# segmatch-mapbuilder / segmatch-mapinfo and core's MapBuilder. The CLI tests run the built tools
# on a dataset and map built once (the MapBuilderFixture entry, their FIXTURES_SETUP).
segmatch_test_suite(test_mapbuilder mapbuilder segmatch_core segmatch_io segmatch_storage segmatch_sim
                    WHOLE_SUITES MapBuilderFixture BagInterop FIXTURE mapbuilder_data FIXTURE_SETUP MapBuilderFixture)
add_dependencies(test_mapbuilder segmatch-mapbuilder segmatch-mapinfo segmatch-sim)
# The default classifier the builder looks for, to know which behaviour to expect.
target_compile_definitions(test_mapbuilder PRIVATE
  SEGMATCH_DEFAULT_MODEL_FOR_TEST="${PROJECT_SOURCE_DIR}/maps/models/default-rf.yml"
  SEGMATCH_OLD_MAP_FOR_TEST="${SEGMATCH_TINY3_MAP}"  # schema 1, unpacked by tests/CMakeLists.txt
  SEGMATCH_SOURCE_DIR="${PROJECT_SOURCE_DIR}")  # tests/tools/bagwriter (BagInterop)
