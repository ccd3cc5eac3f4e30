// Random forest segment matcher (paper III-D, Table I: 25 trees; Breiman 2001). The forest
// classifies the pair vector of pair_features(); the score w is the fraction of trees voting
// "same object", thresholded by filter_matches().
#include "segmatch/core/matching/matcher.h"

#include <opencv2/core.hpp>
#include <opencv2/ml.hpp>

#include <algorithm>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

namespace segmatch {

namespace {
constexpr const char* kFormatTag = "segmatch-random-forest";
constexpr int kFormatVersion = 1;
constexpr int kSame = 1;
constexpr int kDifferent = 0;
}  // namespace

struct RandomForestMatcher::Impl {
  MatcherConfig config;
  cv::Ptr<cv::ml::RTrees> forest;
  int same_column = -1;  // column of class kSame in getVotes() output
  // The forest flattened for fast evaluation (getVotes() costs ~8 us per sample).
  struct FlatNode {
    int var = -1;   // split variable, -1 for a leaf
    float c = 0.f;  // go left if value <= c
    int left = -1, right = -1;
    int same = 0;  // leaf: 1 if the tree votes "same object"
  };
  std::vector<FlatNode> nodes;
  std::vector<int> roots;

  void flatten() {
    nodes.clear();
    roots.clear();
    const auto& cv_nodes = forest->getNodes();
    const auto& splits = forest->getSplits();
    nodes.resize(cv_nodes.size());
    for (size_t i = 0; i < cv_nodes.size(); ++i) {
      const cv::ml::DTrees::Node& n = cv_nodes[i];
      FlatNode& f = nodes[i];
      if (n.split < 0) {
        f.same = n.classIdx == same_column ? 1 : 0;
        continue;
      }
      // Ordered variables only, no surrogates (see train()): the first split decides,
      // exactly as DTreesImpl::predictTrees.
      const cv::ml::DTrees::Split& s = splits[n.split];
      f.var = s.varIdx;
      f.c = s.c;
      f.left = s.inversed ? n.right : n.left;
      f.right = s.inversed ? n.left : n.right;
    }
    roots = forest->getRoots();
    build_complete();
  }

  // The same trees padded to complete binary trees of one depth (a leaf above the bottom
  // becomes a split that always goes left, down to a copy of the leaf): every walk takes
  // `depth` steps of index arithmetic, no branch to mispredict, and walks of several rows
  // interleave. Used when the forest is shallow enough (SegMatch's: max depth 8).
  static constexpr int kMaxCompleteDepth = 12;
  int depth = -1;              // -1: forest too deep, use the node walk
  std::vector<int> split_var;  // per tree 2^depth - 1 splits, heap order
  std::vector<float> split_c;
  std::vector<uint8_t> leaf_same;  // per tree 2^depth leaves

  int depth_of(int n) const {
    return nodes[n].var < 0 ? 0 : 1 + std::max(depth_of(nodes[n].left), depth_of(nodes[n].right));
  }

  void pad(int tree, int n, size_t i, int level) {
    const size_t splits = (size_t{1} << depth) - 1;
    if (level == depth) {
      leaf_same[tree * (splits + 1) + (i - splits)] = static_cast<uint8_t>(nodes[n].same);
      return;
    }
    const bool leaf = nodes[n].var < 0;
    split_var[tree * splits + i] = leaf ? 0 : nodes[n].var;
    split_c[tree * splits + i] = leaf ? std::numeric_limits<float>::infinity() : nodes[n].c;
    pad(tree, leaf ? n : nodes[n].left, 2 * i + 1, level + 1);
    pad(tree, leaf ? n : nodes[n].right, 2 * i + 2, level + 1);
  }

  void build_complete() {
    depth = 0;
    for (int r : roots) depth = std::max(depth, depth_of(r));
    if (depth > kMaxCompleteDepth) {
      depth = -1;
      return;
    }
    const size_t splits = (size_t{1} << depth) - 1;
    split_var.assign(roots.size() * splits, 0);
    split_c.assign(roots.size() * splits, 0.f);
    leaf_same.assign(roots.size() * (splits + 1), 0);
    for (size_t t = 0; t < roots.size(); ++t) pad(static_cast<int>(t), roots[t], 0, 0);
  }

  int votes(const float* x) const {
    int same_votes = 0;
    for (int r : roots) {
      const FlatNode* n = &nodes[r];
      while (n->var >= 0) n = &nodes[x[n->var] <= n->c ? n->left : n->right];
      same_votes += n->same;
    }
    return same_votes;
  }

  // Votes of rows [0, n) of `rows` (dim floats each) into out[0..n).
  void votes(const float* rows, int dim, int n, int* out) const {
    if (depth < 0) {
      for (int i = 0; i < n; ++i) out[i] = votes(rows + static_cast<size_t>(i) * dim);
      return;
    }
    std::vector<int> all(static_cast<size_t>(n));
    std::iota(all.begin(), all.end(), 0);
    std::fill(out, out + n, 0);
    add_votes(rows, dim, all.data(), n, 0, static_cast<int>(roots.size()), out);
  }

  // Adds the "same" votes of trees [t0, t1) to count[idx[j]] for the rows idx[0..m) of `rows`
  // (complete trees only), walking 8 rows at a time.
  void add_votes(const float* rows, int dim, const int* idx, int m, int t0, int t1, int* count) const {
    const size_t splits = (size_t{1} << depth) - 1;
    constexpr int kLanes = 8;  // independent walks in flight
    for (int i0 = 0; i0 < m; i0 += kLanes) {
      const int lanes = std::min(kLanes, m - i0);
      const float* x[kLanes];
      for (int l = 0; l < kLanes; ++l) x[l] = rows + static_cast<size_t>(idx[i0 + std::min(l, lanes - 1)]) * dim;
      int sum[kLanes] = {};
      for (int t = t0; t < t1; ++t) {
        const int* var = split_var.data() + t * splits;
        const float* c = split_c.data() + t * splits;
        size_t at[kLanes] = {};
        for (int d = 0; d < depth; ++d)
          for (int l = 0; l < kLanes; ++l) at[l] = 2 * at[l] + 1 + !(x[l][var[at[l]]] <= c[at[l]]);
        const uint8_t* leaf = leaf_same.data() + t * (splits + 1) - splits;
        for (int l = 0; l < kLanes; ++l) sum[l] += leaf[at[l]];
      }
      for (int l = 0; l < lanes; ++l) count[idx[i0 + l]] += sum[l];
    }
  }

  // Votes of rows [0, n) into out[0..n) where they reach `needed` (<= trees), -1 elsewhere.
  // A row is dropped as soon as more than trees - needed trees voted "different": its final
  // count could no longer reach `needed`. No row can be dropped before trees - needed + 1
  // trees, so all rows walk those first, then the survivors walk kChunk trees at a time.
  void votes_at_least(const float* rows, int dim, int n, int needed, int* out) const {
    const int trees = static_cast<int>(roots.size());
    const int max_no = trees - needed;
    if (depth < 0) {
      for (int i = 0; i < n; ++i) {
        const float* x = rows + static_cast<size_t>(i) * dim;
        int same = 0, no = 0;
        for (int r : roots) {
          const FlatNode* nd = &nodes[r];
          while (nd->var >= 0) nd = &nodes[x[nd->var] <= nd->c ? nd->left : nd->right];
          same += nd->same;
          no += 1 - nd->same;
          if (no > max_no) break;
        }
        out[i] = no > max_no ? -1 : same;
      }
      return;
    }
    constexpr int kChunk = 2;  // of 1, 2 and 4 trees per round, 2 measured fastest
    std::vector<int> idx(n);
    for (int i = 0; i < n; ++i) {
      idx[i] = i;
      out[i] = 0;
    }
    int m = n;
    for (int t = 0; t < trees && m > 0;) {
      const int t1 = std::min(trees, t == 0 ? max_no + 1 : t + kChunk);
      add_votes(rows, dim, idx.data(), m, t, t1, out);
      t = t1;
      int kept = 0;
      for (int j = 0; j < m; ++j) {
        if (t - out[idx[j]] <= max_no)
          idx[kept++] = idx[j];
        else
          out[idx[j]] = -1;
      }
      m = kept;
    }
  }
};

RandomForestMatcher::RandomForestMatcher(const MatcherConfig& config) : impl_(std::make_unique<Impl>()) {
  config.validate();
  impl_->config = config;
  impl_->config.type = MatcherType::kRandomForest;
}
RandomForestMatcher::~RandomForestMatcher() = default;
RandomForestMatcher::RandomForestMatcher(RandomForestMatcher&&) noexcept = default;
RandomForestMatcher& RandomForestMatcher::operator=(RandomForestMatcher&&) noexcept = default;

const MatcherConfig& RandomForestMatcher::config() const { return impl_->config; }

bool RandomForestMatcher::trained() const {
  return impl_ && impl_->forest && impl_->forest->isTrained() && impl_->same_column >= 0;
}

namespace {
// Finds which vote column is the "same object" class (labels are sorted by OpenCV).
int find_same_column(const cv::Ptr<cv::ml::RTrees>& forest, int dim) {
  cv::Mat probe = cv::Mat::zeros(1, dim, CV_32F), votes;
  forest->getVotes(probe, votes, 0);
  for (int c = 0; c < votes.cols; ++c)
    if (votes.at<int>(0, c) == kSame) return c;
  return -1;
}
}  // namespace

void RandomForestMatcher::train(const std::vector<std::pair<const Segment*, const Segment*>>& pairs,
                                const std::vector<bool>& same_object) {
  if (pairs.size() != same_object.size())
    throw std::invalid_argument("RandomForestMatcher::train: pairs and same_object differ in size");
  size_t positives = 0;
  for (bool s : same_object) positives += s ? 1 : 0;
  if (positives == 0 || positives == same_object.size())
    throw std::invalid_argument("RandomForestMatcher::train: needs both positive and negative pairs (got " +
                                std::to_string(positives) + " positives of " + std::to_string(same_object.size()) +
                                ")");
  const MatcherConfig& cfg = impl_->config;
  const int dim = pair_feature_count(cfg.use_shapes);
  cv::Mat samples(static_cast<int>(pairs.size()), dim, CV_32F);
  cv::Mat responses(static_cast<int>(pairs.size()), 1, CV_32S);
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (pairs[i].first == nullptr || pairs[i].second == nullptr)
      throw std::invalid_argument("RandomForestMatcher::train: null segment in pair " + std::to_string(i));
    const std::vector<float> f = pair_features(*pairs[i].first, *pairs[i].second, cfg.use_shapes);
    std::copy(f.begin(), f.end(), samples.ptr<float>(static_cast<int>(i)));
    responses.at<int>(static_cast<int>(i)) = same_object[i] ? kSame : kDifferent;
  }
  cv::Ptr<cv::ml::RTrees> forest = cv::ml::RTrees::create();
  forest->setMaxDepth(cfg.rf_max_depth);
  forest->setMinSampleCount(cfg.rf_min_samples);
  forest->setRegressionAccuracy(0.f);
  forest->setUseSurrogates(false);
  forest->setMaxCategories(2);
  forest->setCalculateVarImportance(false);
  forest->setActiveVarCount(0);  // sqrt(dim) random features per split (Breiman)
  forest->setTermCriteria(cv::TermCriteria(cv::TermCriteria::MAX_ITER, cfg.rf_trees, 0.0));
  // Balanced class priors: training sets hold ~50 negatives per positive (paper IV-B), and
  // without weighting the trees learn the base rate, so a true pair rarely reaches the
  // paper's probability thresholds. Priors are sorted by class label value.
  const double negatives = static_cast<double>(same_object.size() - positives);
  cv::Mat priors(2, 1, CV_32F);
  priors.at<float>(kDifferent < kSame ? 0 : 1) = static_cast<float>(1.0 / negatives);
  priors.at<float>(kDifferent < kSame ? 1 : 0) = static_cast<float>(1.0 / positives);
  forest->setPriors(priors);
  cv::Mat var_type(dim + 1, 1, CV_8U, cv::Scalar(cv::ml::VAR_ORDERED));
  var_type.at<uchar>(dim) = cv::ml::VAR_CATEGORICAL;
  forest->train(cv::ml::TrainData::create(samples, cv::ml::ROW_SAMPLE, responses, cv::noArray(), cv::noArray(),
                                          cv::noArray(), var_type));
  impl_->same_column = find_same_column(forest, dim);
  impl_->forest = forest;
  impl_->flatten();
}

std::vector<float> RandomForestMatcher::probabilities(const std::vector<float>& rows) const {
  if (!trained()) throw std::logic_error("RandomForestMatcher: not trained");
  const int dim = pair_feature_count(impl_->config.use_shapes);
  if (rows.size() % dim != 0) throw std::invalid_argument("RandomForestMatcher::probabilities: row size mismatch");
  const int n = static_cast<int>(rows.size() / dim);
  std::vector<float> out(n, 0.f);
  if (n == 0) return out;
  const float trees = static_cast<float>(impl_->roots.size());
  std::vector<int> votes(n);
  impl_->votes(rows.data(), dim, n, votes.data());
  for (int i = 0; i < n; ++i) out[i] = static_cast<float>(votes[i]) / trees;
  return out;
}

void RandomForestMatcher::probabilities_at_least(const float* rows, size_t n, float min_probability, float* out) const {
  if (!trained()) throw std::logic_error("RandomForestMatcher: not trained");
  if (n > static_cast<size_t>(std::numeric_limits<int>::max()))
    throw std::invalid_argument("RandomForestMatcher::probabilities_at_least: too many rows");
  if (n == 0) return;
  const int dim = pair_feature_count(impl_->config.use_shapes);
  const int trees = static_cast<int>(impl_->roots.size());
  const float ftrees = static_cast<float>(trees);
  // Fewest votes whose probability (computed as in probabilities()) is >= min_probability;
  // the probability only grows with the votes. trees + 1: no count reaches it.
  int needed = trees + 1;
  for (int v = trees; v >= 0 && static_cast<float>(v) / ftrees >= min_probability; --v) needed = v;
  std::vector<int> votes(n);
  if (needed > trees)
    std::fill(votes.begin(), votes.end(), -1);
  else
    impl_->votes_at_least(rows, dim, static_cast<int>(n), needed, votes.data());
  for (size_t i = 0; i < n; ++i) out[i] = votes[i] < 0 ? -1.f : static_cast<float>(votes[i]) / ftrees;
}

std::vector<float> RandomForestMatcher::opencv_probabilities(const std::vector<float>& rows) const {
  if (!trained()) throw std::logic_error("RandomForestMatcher: not trained");
  const int dim = pair_feature_count(impl_->config.use_shapes);
  const int n = static_cast<int>(rows.size() / dim);
  std::vector<float> out(n, 0.f);
  if (n == 0) return out;
  const cv::Mat samples(n, dim, CV_32F, const_cast<float*>(rows.data()));
  cv::Mat votes;
  impl_->forest->getVotes(samples, votes, 0);  // row 0: class labels, then counts per sample
  const float trees = static_cast<float>(impl_->forest->getRoots().size());
  for (int i = 0; i < n; ++i) out[i] = static_cast<float>(votes.at<int>(i + 1, impl_->same_column)) / trees;
  return out;
}

float RandomForestMatcher::probability(const Segment& query, const Segment& target) const {
  if (!trained()) throw std::logic_error("RandomForestMatcher: not trained");
  return probabilities(pair_features(query, target, impl_->config.use_shapes)).front();
}

std::string RandomForestMatcher::save() const {
  if (!trained()) throw std::logic_error("RandomForestMatcher::save: not trained");
  const MatcherConfig& c = impl_->config;
  cv::FileStorage fs(".yml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
  fs << "format" << kFormatTag;
  fs << "version" << kFormatVersion;
  fs << "use_shapes" << static_cast<int>(c.use_shapes);
  fs << "rf_threshold" << c.rf_threshold;
  fs << "rf_trees" << c.rf_trees;
  fs << "rf_max_depth" << c.rf_max_depth;
  fs << "rf_min_samples" << c.rf_min_samples;
  fs << "model"
     << "{";
  impl_->forest->write(fs);
  fs << "}";
  return fs.releaseAndGetString();
}

RandomForestMatcher RandomForestMatcher::load(const std::string& bytes) {
  const std::string what = "RandomForestMatcher::load: ";
  if (bytes.empty()) throw std::runtime_error(what + "empty model bytes");
  try {
    cv::FileStorage fs(bytes, cv::FileStorage::READ | cv::FileStorage::MEMORY);
    if (!fs.isOpened()) throw std::runtime_error(what + "model bytes are not OpenCV FileStorage");
    const cv::FileNode format = fs["format"];
    if (!format.isString() || format.string() != kFormatTag)
      throw std::runtime_error(what + "not a SegMatch random forest model (missing format tag '" + kFormatTag + "')");
    const int version = static_cast<int>(fs["version"].real());
    if (version != kFormatVersion)
      throw std::runtime_error(what + "unsupported model version " + std::to_string(version) + " (expected " +
                               std::to_string(kFormatVersion) + ")");
    MatcherConfig c;
    c.type = MatcherType::kRandomForest;
    c.use_shapes = static_cast<int>(fs["use_shapes"].real()) != 0;
    c.rf_threshold = static_cast<float>(fs["rf_threshold"].real());
    c.rf_trees = static_cast<int>(fs["rf_trees"].real());
    c.rf_max_depth = static_cast<int>(fs["rf_max_depth"].real());
    c.rf_min_samples = static_cast<int>(fs["rf_min_samples"].real());
    c.validate();
    RandomForestMatcher m(c);
    cv::Ptr<cv::ml::RTrees> forest = cv::ml::RTrees::create();
    forest->read(fs["model"]);
    if (!forest->isTrained() || forest->getVarCount() != pair_feature_count(c.use_shapes))
      throw std::runtime_error(what + "model section is missing or has the wrong input size");
    m.impl_->same_column = find_same_column(forest, pair_feature_count(c.use_shapes));
    if (m.impl_->same_column < 0) throw std::runtime_error(what + "model has no 'same' class");
    m.impl_->forest = forest;
    m.impl_->flatten();
    return m;
  } catch (const cv::Exception& e) {
    throw std::runtime_error(what + "corrupt model bytes (" + e.msg + ")");
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(what + "invalid configuration in model (" + e.what() + ")");
  }
}

}  // namespace segmatch
