// segmatch-loop's scoring (loop/src/loop_eval.cpp) on a route with a known revisit: loops with
// known errors give the precision and recall expected at every translation threshold.
#include "loop_eval.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace segmatch;

namespace {

// 201 frames out along x (1 m apart), then 200 back 0.5 m to the side: frame q > 200 is at
// x = 400 - q, and it revisits frame 400 - q driven more than 150 m before once q > 275.
Poses out_and_back() {
  Poses truth;
  for (int q = 0; q <= 400; ++q) {
    Pose3d T = Pose3d::Identity();
    T.translation() = q <= 200 ? Eigen::Vector3d(q, 0, 0) : Eigen::Vector3d(400 - q, 0.5, 0);
    if (q > 200) T.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    truth.push_back(T);
  }
  return truth;
}

// A loop q -> m whose transform is off by `error` (T_query_match = T_true * error^-1).
LoopClosure loop_with_error(const Poses& truth, size_t q, size_t m, const Pose3d& error) {
  LoopClosure l;
  l.query_frame = q;
  l.match_frame = m;
  l.T_query_match = truth[q].inverse() * truth[m] * error.inverse();
  return l;
}

Pose3d shifted(double x_m) {
  Pose3d T = Pose3d::Identity();
  T.translation().x() = x_m;
  return T;
}

}  // namespace

TEST(LoopEvaluation, PrecisionAndRecallAtEveryTranslationThreshold) {
  const Poses truth = out_and_back();
  std::vector<size_t> processed;
  for (size_t f = 10; f <= 400; f += 10) processed.push_back(f);
  Pose3d turned = Pose3d::Identity();
  turned.linear() = Eigen::AngleAxisd(10.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const std::vector<LoopClosure> loops = {
      loop_with_error(truth, 300, 100, shifted(0.03)),  // true from 0.05 m on
      loop_with_error(truth, 320, 80, shifted(0.3)),    // from 0.5 m on
      loop_with_error(truth, 350, 50, shifted(3.0)),    // only at 5 m
      loop_with_error(truth, 380, 20, turned),          // 10 deg off: never
  };
  loop::EvalConfig c;
  c.curve_translation_m = {0.05, 0.5, 1.0, 5.0};
  const loop::Evaluation e = loop::evaluate(loops, processed, truth, 0, c);

  EXPECT_EQ(e.revisit_clouds, 13u) << "frames 280, 290, .., 400";
  EXPECT_EQ(e.true_loops, 2u);
  EXPECT_EQ(e.false_loops, 2u);
  ASSERT_EQ(e.curve.size(), 4u);
  const size_t expected_true[] = {1, 2, 2, 3};
  for (size_t k = 0; k < e.curve.size(); ++k) {
    SCOPED_TRACE("threshold " + std::to_string(c.curve_translation_m[k]));
    EXPECT_EQ(e.curve[k].true_loops, expected_true[k]);
    EXPECT_DOUBLE_EQ(e.curve[k].precision, expected_true[k] / 4.0);
    EXPECT_EQ(e.curve[k].detected_revisit_clouds, expected_true[k]);
    EXPECT_DOUBLE_EQ(e.curve[k].recall, expected_true[k] / 13.0);
  }
  // The configured 1 m threshold is the headline figure.
  EXPECT_DOUBLE_EQ(e.precision, e.curve[2].precision);
  EXPECT_DOUBLE_EQ(e.recall, e.curve[2].recall);
}
