#include "segmatch/io/auto_profile.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

namespace segmatch {
namespace io {
namespace {

double round_to(double v, double step) { return std::round(v / step) * step; }

// Segmentation of sparse inputs (../shared/data/README.md): our grid takes their median point
// spacing as its leaf (rounded to 5 cm, 0.2..0.5 m: both validated classes work at 0.2 m, and
// finer voxels than the points only split segments) with one point per voxel; clusters join
// points two leaves apart; segments need as many voxels as 30 do at 0.2 m over the same area.
void fit_segmentation_to_spacing(PipelineConfig& c, const InputMeasurements& m) {
  SegmentationConfig& s = c.localizer.segmentation;
  const float leaf = static_cast<float>(std::clamp(round_to(m.spacing_p50_m, 0.05), 0.2, 0.5));
  s.voxel.leaf_m = leaf;
  s.voxel.min_points_per_voxel = 1;
  s.segmenter.cluster_distance_m = 2.0f * leaf;
  s.segmenter.min_points = std::max(10, static_cast<int>(std::lround(30.0 * (0.2 / leaf) * (0.2 / leaf))));
  // Keyframes metres apart are each worth keeping; the paper's one scan per metre is for raw
  // 10 Hz scans.
  if (m.scan_distance_m >= 1.0) c.local_cloud.min_travel_between_scans_m = 0.0;
  c.localizer.min_confidence = 0.0f;  // kitti-hdl64's 0.8 was chosen on dense simulated clouds
}

// A ring field (a ROS 2 PointCloud2's "ring") names each point's beam: the ring count and
// spacing come from it instead of the elevation histogram, which noise or a tilted mount can
// blur. Per scan, each ring's median elevation; the scan with the most rings decides.
void rings_from_field(const std::vector<PointCloud>& scans, const std::vector<std::vector<uint16_t>>& rings,
                      InputMeasurements& m) {
  size_t best = 0;
  double spacing_deg = 0.0;
  for (size_t s = 0; s < scans.size(); ++s) {
    if (rings[s].size() != scans[s].size() || scans[s].empty()) continue;
    std::map<uint16_t, std::vector<double>> by_ring;
    for (size_t i = 0; i < scans[s].size(); ++i) {
      const Point& p = scans[s][i];
      by_ring[rings[s][i]].push_back(std::atan2(p.z, std::hypot(p.x, p.y)) * 180.0 / M_PI);
    }
    std::vector<double> centres;
    for (auto& [ring, e] : by_ring) {
      std::nth_element(e.begin(), e.begin() + e.size() / 2, e.end());
      centres.push_back(e[e.size() / 2]);
    }
    std::sort(centres.begin(), centres.end());
    if (centres.size() <= best) continue;
    best = centres.size();
    std::vector<double> steps;
    for (size_t k = 1; k < centres.size(); ++k) steps.push_back(centres[k] - centres[k - 1]);
    std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
    spacing_deg = steps.empty() ? 0.0 : steps[steps.size() / 2];
  }
  if (best < 2) return;
  m.ring_count = static_cast<double>(best);
  m.ring_spacing_deg = spacing_deg;
}

}  // namespace

InputMeasurements measure_sequence(const Sequence& sequence, size_t first, size_t last, size_t stride,
                                   const InputProfileConfig& config) {
  if (sequence.size() == 0) throw std::invalid_argument(sequence.folder() + ": no scans to measure");
  last = std::min(last, sequence.size() - 1);
  stride = std::max<size_t>(1, stride);
  std::vector<size_t> used;
  for (size_t i = first; i <= last; i += stride) used.push_back(i);
  if (used.empty()) throw std::invalid_argument(sequence.folder() + ": no scans in the range to measure");
  Poses poses;
  for (size_t i : used) poses.push_back(sequence.poses()[i]);
  std::vector<PointCloud> scans;
  std::vector<std::vector<uint16_t>> rings;
  for (size_t k : scans_to_measure(used.size(), config)) {
    CloudData scan = sequence.scan(used[k]);
    scans.push_back(std::move(scan.points));
    rings.push_back(std::move(scan.rings));
  }
  InputMeasurements m = measure_input(scans, poses, config);
  rings_from_field(scans, rings, m);
  // Pose agreement is a property of the recording: consecutive scans of the sequence over the
  // range, up to kMaxPairs of them spread evenly.
  constexpr size_t kMaxPairs = 100;
  const size_t span = last > first ? last - first : 0;
  PointCloud a, b;
  size_t loaded = SIZE_MAX;  // index held in b (consecutive pairs reuse it as the next a)
  for (size_t k = 0; k < std::min(span, kMaxPairs); ++k) {
    const size_t i = first + (span <= kMaxPairs ? k : k * span / kMaxPairs);
    a = loaded == i ? std::move(b) : sequence.scan(i).points;
    b = sequence.scan(i + 1).points;
    loaded = i + 1;
    check_pose_agreement({{&a, &b, sequence.poses()[i], sequence.poses()[i + 1], i}}, m);
  }
  return m;
}

PipelineConfig auto_pipeline_config(const InputMeasurements& m) {
  PipelineConfig c = pipeline_preset("kitti-hdl64");  // dense-spinning: the paper's values
  const std::string sensor = m.sensor_class();
  if (sensor == "sparse-spinning") {
    fit_segmentation_to_spacing(c, m);
    // riverside02 keyframes 0-140 (docs/how-defaults-were-chosen.md): the simulation-trained forest
    // at 0.72 passes half the true pairs it sees on sparse real segments; 0.6 over k = 500
    // passes more, and support 14 keeps the look-alikes that then verify out.
    c.localizer.retrieval.k = 500;
    c.localizer.matcher.rf_threshold = 0.6f;
    c.localizer.min_refine_fitness = 0.3f;
    c.localizer.min_support = 14;
    // With a prior (tracking, GNSS) the poses are confined to where the vehicle is: on
    // riverside02 0-140 tracked, fitness >= 0.1 instead of 0.3 took 31 -> 36 of 45, 0 false;
    // support 8 instead of 14 gave 2 false in 141-280, so support stays. With 30 m GNSS priors
    // one pose 4 m off passed at confidence 0.07 (true ones: >= 0.12), hence a floor of 0.1;
    // since raised to the default's 0.35 (wrong priors, see PipelineConfig()).
    c.localizer.min_refine_fitness_with_prior = 0.1f;
    c.localizer.min_confidence_with_prior = 0.35f;
  } else if (sensor == "narrow-fov") {
    fit_segmentation_to_spacing(c, m);
    // A small field of view sees few segments: a cylinder of three times the median range
    // (hku-loop1 and hku-mb: 10.3 m -> 30 m, livox-keyframes' swept value), at most the
    // paper's 60 m, and every keyframe kept (each sees a place only briefly).
    c.local_cloud.radius_m = std::clamp(round_to(3.0 * m.range_p50_m, 5.0), 20.0, 60.0);
    c.local_cloud.min_travel_between_scans_m = 0.0;
    c.localizer.segmentation.segmenter.min_points = std::max(10, c.localizer.segmentation.segmenter.min_points * 2 / 3);
    // livox-keyframes' matching (chosen on hku-loop1, checked on hku-mb): loose matches whose
    // centroids may move by ~1 m between passes, settled by support and, in loop closure, by
    // the odometry drift bound. L2: no classifier was trained on Livox segments.
    c.localizer.matcher.type = MatcherType::kL2;
    c.localizer.matcher.use_shapes = false;
    c.localizer.matcher.l2_threshold = 3.0f;
    c.localizer.verification.resolution_m = 0.7f;
    c.localizer.min_support = 4;
    // With a prior the ambiguity check no longer sees the look-alikes elsewhere: on hku-mb,
    // priors 4-10 m off (radius 3 m, --wrong-prior-m) were answered at support 6-13, all false,
    // GNSS-like priors (sigma 3 and 10 m) at 38 or more when true, 9 when false: 14, as the
    // sparse-spinning profile asks everywhere. Chosen on hku-mb; on hku-loop1's revisit (few
    // queries) tracking still localizes 4 of 6, as before, registration answering under priors.
    c.localizer.min_support_with_prior = 14;
    // The L2 gate at 3.0 passes most candidates, so verification grows with k: on hku-mb
    // (even / odd keyframes) k 200 -> 50 took it from 682 to 57 ms per query for 38 -> 37 of
    // 39 localized; hku-loop1's revisit 2 -> 3 of 6, loops 3 -> 2 true, 0 false on both.
    c.localizer.retrieval.k = 50;
  }
  c.preset = "auto";
  c.measured = m;
  take_measured_elevations(c);
  c.validate();
  return c;
}

std::string describe_profile(const PipelineConfig& c) {
  char buf[1024];
  std::string out;
  if (c.measured) {
    const InputMeasurements& m = *c.measured;
    std::snprintf(buf, sizeof buf,
                  "measured (%zu scans): %.0f points per scan, %.0f%% of the horizon, elevation %.1f..%.1f deg, "
                  "range median %.1f m / p95 %.1f m, point spacing p10 %.3f m / median %.3f m (%.4f per m of range), "
                  "%.2f m between scans\n",
                  m.scans_measured, m.points_per_scan, 100.0 * m.azimuth_coverage, m.elevation_min_deg,
                  m.elevation_max_deg, m.range_p50_m, m.range_p95_m, m.spacing_p10_m, m.spacing_p50_m,
                  m.spacing_per_range, m.scan_distance_m);
    out += buf;
    out += "sensor class: " + m.sensor_class() + (m.downsampled ? " (already downsampled)" : " (raw scans)") + "\n";
    if (m.ring_count > 0)
      std::snprintf(buf, sizeof buf, "beam layout: %s, %.0f rings %.2f deg apart\n", m.beam_layout().c_str(),
                    m.ring_count, m.ring_spacing_deg);
    else
      std::snprintf(buf, sizeof buf, "beam layout: %s\n", m.beam_layout().c_str());
    out += buf;
    if (m.pairs_checked > 0) {
      std::snprintf(buf, sizeof buf, "poses against scans: %zu of %zu consecutive pairs checked agree\n",
                    m.pairs_checked - m.pairs_disagreeing, m.pairs_checked);
      out += buf;
    }
    if (m.pairs_disagreeing > 0) {
      std::string where;
      for (size_t k = 0; k < m.disagreeing_pairs.size() && k < 12; ++k)
        where += (k ? ", " : "") + std::to_string(m.disagreeing_pairs[k]);
      if (m.disagreeing_pairs.size() > 12) where += ", ...";
      std::snprintf(
          buf, sizeof buf,
          "WARNING: at %zu pairs the poses disagree with the scans (under %.0f%% of a scan within %.2f m of "
          "the previous one): scans %s; segments there are smeared and queries there are unlikely to localize; "
          "check the trajectory (e.g. re-run its SLAM) before relying on a map of these stretches\n",
          m.pairs_disagreeing, 100.0 * InputMeasurements::kMinAgreement, InputMeasurements::kAgreementRadiusM,
          where.c_str());
      out += buf;
    }
  }
  return out + describe_choice(c);
}

std::string describe_choice(const PipelineConfig& c) {
  char buf[1024];
  const SegmentationConfig& s = c.localizer.segmentation;
  const LocalizerConfig& l = c.localizer;
  std::snprintf(buf, sizeof buf,
                "chose (%s): %.0f m cylinder, a scan every %.1f m; voxels %.2f m with >= %d points; clusters %.2f m, "
                "%d..%d points; k %d; %s; verification %.2f m, support >= %d, confidence >= %.2f",
                c.preset.c_str(), c.local_cloud.radius_m, c.local_cloud.min_travel_between_scans_m, s.voxel.leaf_m,
                s.voxel.min_points_per_voxel, s.segmenter.cluster_distance_m, s.segmenter.min_points,
                s.segmenter.max_points, l.retrieval.k,
                l.matcher.type == MatcherType::kL2
                    ? ("L2 matcher < " + std::to_string(l.matcher.l2_threshold).substr(0, 4)).c_str()
                    : ("random forest >= " + std::to_string(l.matcher.rf_threshold).substr(0, 4) +
                       (l.matcher.use_shapes ? " (eigen+shapes)" : " (eigen)"))
                          .c_str(),
                l.verification.resolution_m, l.min_support, l.min_confidence);
  return buf;
}

}  // namespace io
}  // namespace segmatch
