// Private: exact 3D nearest-neighbour search over a point cloud (FLANN KDTreeSingleIndex),
// used by refine_alignment(). Not thread-safe per instance (reuses its result buffers).
#pragma once

#include "segmatch/core/types.h"

#include <flann/flann.hpp>

#include <memory>
#include <vector>

namespace segmatch {
namespace detail {

class PointTree {
 public:
  explicit PointTree(const PointCloud& cloud) : xyz_(cloud.size() * 3) {
    for (size_t i = 0; i < cloud.size(); ++i) {
      xyz_[3 * i] = cloud[i].x;
      xyz_[3 * i + 1] = cloud[i].y;
      xyz_[3 * i + 2] = cloud[i].z;
    }
    if (!cloud.empty()) {
      flann::Matrix<float> m(xyz_.data(), cloud.size(), 3);
      tree_ = std::make_unique<flann::KDTreeSingleIndex<flann::L2_Simple<float>>>(
          m, flann::KDTreeSingleIndexParams(/*leaf_max_size=*/10, /*reorder=*/true));
      tree_->buildIndex();
    }
    params_.eps = 0.f;
    params_.sorted = true;
  }

  size_t size() const { return xyz_.size() / 3; }
  const float* point(size_t i) const { return &xyz_[3 * i]; }

  // Nearest point: returns false for an empty cloud.
  bool nearest(const float* p, size_t& index, float& sq_dist) {
    if (!tree_) return false;
    nn_.clear();
    tree_->findNeighbors(nn_, p, params_);
    nn_.copy(&index, &sq_dist, 1);
    return nn_.size() == 1;
  }

  // Up to k nearest points (k must not change between calls on one instance); returns count.
  size_t knn(const float* p, size_t k, std::vector<size_t>& index, std::vector<float>& sq_dist) {
    if (!tree_) return 0;
    if (!knn_ || knn_k_ != k) {
      knn_ = std::make_unique<flann::KNNSimpleResultSet<float>>(k);
      knn_k_ = k;
    }
    knn_->clear();
    tree_->findNeighbors(*knn_, p, params_);
    index.resize(k);
    sq_dist.resize(k);
    knn_->copy(index.data(), sq_dist.data(), k);
    return knn_->size();
  }

 private:
  std::vector<float> xyz_;
  std::unique_ptr<flann::KDTreeSingleIndex<flann::L2_Simple<float>>> tree_;
  flann::SearchParams params_;
  flann::KNNSimpleResultSet<float> nn_{1};
  std::unique_ptr<flann::KNNSimpleResultSet<float>> knn_;
  size_t knn_k_ = 0;
};

}  // namespace detail
}  // namespace segmatch
