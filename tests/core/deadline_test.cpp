// A query's deadline (core/deadline.h, a server's --request-timeout-s): a passed deadline stops
// the localizer at its next stage boundary with a typed refusal; a deadline that does not pass
// changes nothing.
#include "segmatch/core/common/deadline.h"
#include "segmatch/core/description/descriptors.h"
#include "segmatch/core/localization/localizer.h"
#include "support/street_scene.h"

#include <gtest/gtest.h>

#include <thread>

namespace segmatch {
namespace {

const Eigen::Vector3f kSensor(25, 0, 2);

const Localizer& street_localizer() {
  static const LocalizerConfig c = test::street_localizer_config();
  static const Localizer localizer(c, extract_segments(test::pole_street(true), kSensor, c.segmentation));
  return localizer;
}

PointCloud street_query() {
  return test::transformed(test::pole_street(true), Pose3d(Eigen::Translation3d(0.3, -0.2, 0)));
}

TEST(Deadline, NeverAndNonPositiveDurationsDoNotPass) {
  EXPECT_FALSE(Deadline().passed());
  EXPECT_FALSE(Deadline().is_set());
  EXPECT_FALSE(Deadline::after_s(0.0).is_set());
  EXPECT_FALSE(Deadline::after_s(-1.0).is_set());
  EXPECT_FALSE(Deadline::after_s(std::nan("")).is_set());
  EXPECT_FALSE(Deadline::after_s(1e300).is_set());
  EXPECT_FALSE(Deadline::after_s(3600.0).passed());
  EXPECT_TRUE(Deadline::at(Deadline::Clock::now()).passed());
  const Deadline soon = Deadline::after_s(0.002);
  std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_TRUE(soon.passed());
}

TEST(Deadline, APassedDeadlineStopsTheQueryBeforeItsFirstStage) {
  const PointCloud query = street_query();
  const LocalizationResult r =
      street_localizer().localize(query, kSensor, CloudKind::kRaw, nullptr, Deadline::at(Deadline::Clock::now()));
  EXPECT_FALSE(r.localized());
  EXPECT_EQ(r.refusal, Refusal::kDeadlinePassed);
  EXPECT_EQ(r.reason, "the query's deadline passed before segmentation");
  EXPECT_EQ(r.query_segments, 0u);
  EXPECT_EQ(r.timings.voxel_ms, 0.0);  // nothing ran
  EXPECT_STREQ(to_string(r.refusal), "deadline_passed");
}

TEST(Deadline, APassedDeadlineStopsASegmentsQueryBeforeRetrieval) {
  const LocalizerConfig& c = street_localizer().config();
  Segments segments = extract_segments(street_query(), kSensor, c.segmentation);
  ASSERT_GE(segments.size(), 10u);
  const LocalizationResult r = street_localizer().localize_segments(std::move(segments), kSensor, nullptr, {},
                                                                    Deadline::at(Deadline::Clock::now()));
  EXPECT_EQ(r.refusal, Refusal::kDeadlinePassed);
  EXPECT_EQ(r.reason, "the query's deadline passed before retrieval");
  EXPECT_EQ(r.candidates, 0u);
}

TEST(Deadline, ADistantDeadlineGivesTheSameAnswerAsNone) {
  const PointCloud query = street_query();
  const LocalizationResult none = street_localizer().localize(query, kSensor);
  const LocalizationResult distant =
      street_localizer().localize(query, kSensor, CloudKind::kRaw, nullptr, Deadline::after_s(3600));
  ASSERT_TRUE(none.localized()) << none.reason;
  EXPECT_TRUE(distant.localized()) << distant.reason;
  EXPECT_EQ(distant.refusal, Refusal::kNone);
  EXPECT_TRUE(distant.T_map_query.isApprox(none.T_map_query, 1e-12));
  EXPECT_EQ(distant.support, none.support);
}

// Description stops between segments once the deadline has passed: the rest stay undescribed
// (the localizer then refuses the query instead of matching a partial description).
TEST(Deadline, DescriptionStopsBetweenSegments) {
  const LocalizerConfig& c = street_localizer().config();
  Segments segments = extract_segments(street_query(), kSensor, c.segmentation);
  ASSERT_FALSE(segments.empty());
  for (Segment& s : segments) s.has_eigen = false;
  describe_segments(segments, c.segmentation.descriptors, Deadline::at(Deadline::Clock::now()));
  for (const Segment& s : segments) EXPECT_FALSE(s.has_eigen);
  describe_segments(segments, c.segmentation.descriptors, Deadline::after_s(3600));
  for (const Segment& s : segments) EXPECT_TRUE(s.has_eigen);
}

}  // namespace
}  // namespace segmatch
