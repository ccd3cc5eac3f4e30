// The shared world the server suites use (server_world.h): built once (CTest's ServerWorld entry
// is their FIXTURES_SETUP), and stored queries read back exactly as written.
#include "server/server_test_util.h"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>

using namespace segmatch;
using namespace segmatch::testing;

TEST(ServerWorld, HoldsAMapAndRevisitQueries) {
  const TestWorld& world = test_world();
  EXPECT_GT(std::filesystem::file_size(world.map_path), 0u);
  ASSERT_GE(world.queries().size(), 5u);
  for (const Query& q : world.queries()) {
    EXPECT_GT(q.request.points.size(), 1000u) << q.frame;
    EXPECT_EQ(q.request.request_id, q.frame);
  }
}

TEST(ServerWorld, StoredQueriesReadBackBitForBit) {
  const TestWorld& world = test_world();
  const std::string path = world.folder + "/queries-again.bin";
  const std::vector<Query> some(world.queries().begin(), world.queries().begin() + 3);
  write_queries(path, some);
  const std::vector<Query> again = read_queries(path);
  ASSERT_EQ(again.size(), some.size());
  for (size_t i = 0; i < again.size(); ++i) {
    const Query &a = some[i], &b = again[i];
    EXPECT_EQ(a.frame, b.frame);
    EXPECT_TRUE(a.T_local_sensor.matrix() == b.T_local_sensor.matrix());
    EXPECT_TRUE(a.T_world_sensor.matrix() == b.T_world_sensor.matrix());
    EXPECT_TRUE(a.request.sensor_position_local == b.request.sensor_position_local);
    // The codec normalises the quaternion on both ends: at most an ulp or two apart.
    EXPECT_LT((a.request.sensor_orientation_local.coeffs() - b.request.sensor_orientation_local.coeffs()).norm(),
              1e-15);
    ASSERT_EQ(a.request.points.size(), b.request.points.size());
    EXPECT_EQ(0,
              std::memcmp(a.request.points.data(), b.request.points.data(), a.request.points.size() * sizeof(Point)));
  }
}

TEST(ServerWorld, ATruncatedQueryFileIsRefusedNamingIt) {
  const TestWorld& world = test_world();
  const std::string path = world.folder + "/queries-cut.bin";
  write_queries(path, {world.queries().front()});
  std::filesystem::resize_file(path, std::filesystem::file_size(path) - 7);
  try {
    read_queries(path);
    FAIL() << "a truncated file was read";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("queries-cut.bin"), std::string::npos) << e.what();
  }
}
