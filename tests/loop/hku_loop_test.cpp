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
  std::vector<double> odometer_m;  // per frame
};

// The livox-keyframes preset with its loop settings (io::loop_detector_config: a local cloud
// every metre, the last 25 m of driving excluded and at most 25 m of scans in the query, loops
// with >= 4 inliers, confidence >= 0.3 and an odometry drift bound of 1 m / 2 deg; the
// odometry drifts 0.3 m / 0.4 deg over this loop), as the README's hku-loop1 command.
HkuRun run_hku() {
  io::SequenceOptions options;
  options.poses_path = kDir + "/odom_poses.txt";
  const io::Sequence seq = io::Sequence::open(kDir, options);
  const LoopDetectorConfig c = io::loop_detector_config(io::pipeline_preset("livox-keyframes"));
  LoopDetector detector(c);
  HkuRun r;
  for (size_t i = 0; i < seq.size(); ++i) {
    r.clouds += detector.process(seq.scan(i).points, seq.poses()[i], i, seq.times()[i]).processed;
    r.odometer_m.push_back(detector.odometer_m());
  }
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

// The end (keyframes ~274-313) revisits the start (0-43): the issue asks for every revisit
// of a mapped place to be detected within 50 m of driving into it.
TEST_F(HkuLoop, RevisitIsDetectedWithin50m) {
  const HkuRun r = run_hku();
  constexpr size_t kRevisitBegin = 274;
  size_t in_revisit = 0;
  double first_after_m = -1;
  for (const LoopClosure& l : r.loops) {
    if (l.query_frame < kRevisitBegin || !accurate(l, r.truth)) continue;
    if (++in_revisit == 1) first_after_m = r.odometer_m[l.query_frame] - r.odometer_m[kRevisitBegin];
  }
  std::printf("[hku] %zu true loops from the revisit, the first %.1f m into it\n", in_revisit, first_after_m);
  ASSERT_GE(in_revisit, 1u);
  EXPECT_LE(first_after_m, 50.0);
}
