// Online loop-closure detection on real data with the default (auto) profile: hku-loop1 (Livox
// Avia, 314 keyframes on a 64 m loop; keyframes ~274-313 revisit 0-43 within 0.1-0.4 m,
// ../shared/data/README.md) and hku-mb (the same sensor, 95 m without a revisit), with their
// odometry-only poses as the vehicle's odometry and the loop-closed poses as ground truth.
#include "segmatch/core/loop/loop_closure.h"
#include "segmatch/io/auto_profile.h"
#include "segmatch/io/pipeline_config.h"
#include "segmatch/io/pose_io.h"
#include "segmatch/io/sequence.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

using namespace segmatch;

namespace {

const std::string kReal = std::string(SEGMATCH_SHARED_DATA_DIR) + "/real";
const std::string kDir = kReal + "/hku-loop1";

struct HkuRun {
  std::vector<LoopClosure> loops;
  Poses truth;
  size_t clouds = 0;
  std::vector<double> odometer_m;  // per frame
};

// What segmatch-loop runs without --preset or loop options: the auto profile measured from the
// recording (narrow-fov: a local cloud every metre, 2.5 x the median range of recent past and
// history, >= 4 inliers, confidence >= 0.3, a drift bound of 1.5 % of the distance driven).
HkuRun run_auto(const std::string& dir) {
  io::SequenceOptions options;
  options.poses_path = dir + "/odom_poses.txt";
  const io::Sequence seq = io::Sequence::open(dir, options);
  const io::PipelineConfig p = io::auto_pipeline_config(io::measure_sequence(seq));
  LoopDetector detector(io::loop_detector_config(p));
  HkuRun r;
  for (size_t i = 0; i < seq.size(); ++i) {
    r.clouds += detector.process(seq.scan(i).points, seq.poses()[i], i, seq.times()[i]).processed;
    r.odometer_m.push_back(detector.odometer_m());
  }
  r.loops = detector.loops();
  r.truth = io::read_kitti_poses(dir + "/poses.txt");
  return r;
}

bool accurate(const LoopClosure& l, const Poses& truth) {
  const Pose3d E = l.T_query_match.inverse() * (truth[l.query_frame].inverse() * truth[l.match_frame]);
  const double deg = Eigen::AngleAxisd(E.linear()).angle() * 180.0 / M_PI;
  std::printf("[hku] loop %zu -> %zu: %zu inliers, confidence %.2f, error %.3f m %.2f deg\n", l.query_frame,
              l.match_frame, l.inliers, l.confidence, E.translation().norm(), deg);
  return E.translation().norm() <= 1.0 && deg <= 3.0;
}

// Each recording is run once per suite (a few seconds each).
class HkuLoop : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!std::filesystem::exists(kDir) || !std::filesystem::exists(kReal + "/hku-mb")) return;
    loop1_ = new HkuRun(run_auto(kDir));
    mb_ = new HkuRun(run_auto(kReal + "/hku-mb"));
  }
  static void TearDownTestSuite() {
    delete loop1_;
    delete mb_;
    loop1_ = mb_ = nullptr;
  }
  void SetUp() override {
    if (!loop1_) GTEST_SKIP() << kReal << "/hku-loop1 or hku-mb is absent (real data is not in the repository)";
  }
  static HkuRun* loop1_;
  static HkuRun* mb_;
};
HkuRun* HkuLoop::loop1_ = nullptr;
HkuRun* HkuLoop::mb_ = nullptr;

}  // namespace

TEST_F(HkuLoop, NoFalseLoop) {
  const HkuRun& r = *loop1_;
  std::printf("[hku] %zu local clouds, %zu loops\n", r.clouds, r.loops.size());
  ASSERT_GT(r.clouds, 40u);
  for (const LoopClosure& l : r.loops) EXPECT_TRUE(accurate(l, r.truth)) << "false loop " << l.query_frame;
}

// The end (keyframes ~274-313) revisits the start (0-43): the issue asks for every revisit
// of a mapped place to be detected within 50 m of driving into it.
TEST_F(HkuLoop, RevisitIsDetectedWithin50m) {
  const HkuRun& r = *loop1_;
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

// hku-mb never returns to its start: any loop is false (a setting found on
// hku-loop1 must hold on the second Livox recording).
TEST_F(HkuLoop, SecondLivoxRecordingHasNoLoop) {
  const HkuRun& r = *mb_;
  std::printf("[hku-mb] %zu local clouds, %zu loops\n", r.clouds, r.loops.size());
  ASSERT_GT(r.clouds, 40u);
  for (const LoopClosure& l : r.loops) EXPECT_TRUE(accurate(l, r.truth)) << "false loop " << l.query_frame;
}
