#include "segmatch/server/metrics.h"

#include <prometheus/collectable.h>
#include <prometheus/counter.h>
#include <prometheus/exposer.h>
#include <prometheus/family.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <prometheus/metric_family.h>
#include <prometheus/registry.h>
#include <prometheus/text_serializer.h>

#include <chrono>
#include <mutex>
#include <stdexcept>

namespace segmatch {
namespace server {
namespace {

// What is read at scrape time: the map being served and the uptime.
class StateCollectable : public prometheus::Collectable {
 public:
  void set_map(const std::string& name, int schema, size_t segments) {
    std::lock_guard<std::mutex> lock(mutex_);
    name_ = name, schema_ = schema, segments_ = segments;
  }
  std::vector<prometheus::MetricFamily> Collect() const override {
    prometheus::MetricFamily map{
        "segmatch_map_info", "The map being served (value 1)", prometheus::MetricType::Gauge, {}};
    prometheus::ClientMetric m;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      m.label = {{"name", name_}, {"schema", std::to_string(schema_)}, {"segments", std::to_string(segments_)}};
    }
    m.gauge.value = 1.0;
    map.metric.push_back(m);
    prometheus::MetricFamily uptime{
        "segmatch_uptime_seconds", "Seconds since the server started", prometheus::MetricType::Gauge, {}};
    prometheus::ClientMetric u;
    u.gauge.value = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    uptime.metric.push_back(u);
    return {map, uptime};
  }

 private:
  mutable std::mutex mutex_;
  std::string name_;
  int schema_ = 0;
  size_t segments_ = 0;
  const std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

}  // namespace

struct Metrics::Impl {
  std::shared_ptr<prometheus::Registry> registry = std::make_shared<prometheus::Registry>();
  std::shared_ptr<StateCollectable> state = std::make_shared<StateCollectable>();
  prometheus::Family<prometheus::Counter>& requests = prometheus::BuildCounter()
                                                          .Name("segmatch_requests_total")
                                                          .Help("Frames answered, by type and status")
                                                          .Register(*registry);
  prometheus::Family<prometheus::Counter>& errors = prometheus::BuildCounter()
                                                        .Name("segmatch_errors_total")
                                                        .Help("ERROR replies, by protocol code")
                                                        .Register(*registry);
  // Buckets from 5 ms (a segments query) to 30 s (the default request timeout).
  prometheus::Histogram& duration = prometheus::BuildHistogram()
                                        .Name("segmatch_request_duration_seconds")
                                        .Help("LOCALIZE and LOCALIZE_SEGMENTS, frame received to reply ready")
                                        .Register(*registry)
                                        .Add({}, prometheus::Histogram::BucketBoundaries{0.005, 0.01, 0.025, 0.05, 0.1,
                                                                                         0.25, 0.5, 1, 2.5, 5, 10, 30});
  prometheus::Gauge& in_flight = prometheus::BuildGauge()
                                     .Name("segmatch_in_flight_requests")
                                     .Help("Localizations received and not yet answered")
                                     .Register(*registry)
                                     .Add({});
  prometheus::Gauge& connections =
      prometheus::BuildGauge().Name("segmatch_connections").Help("Connections open").Register(*registry).Add({});
  std::unique_ptr<prometheus::Exposer> exposer;
};

Metrics::Metrics(const std::string& listen_address, uint16_t port) : impl_(std::make_unique<Impl>()) {
  const bool v6 = listen_address.find(':') != std::string::npos;
  const std::string bind = (v6 ? "[" + listen_address + "]" : listen_address) + ":" + std::to_string(port);
  try {
    impl_->exposer = std::make_unique<prometheus::Exposer>(bind, 1);
  } catch (const std::exception& e) {
    throw std::runtime_error("cannot serve metrics on " + bind + ": " + e.what());
  }
  impl_->exposer->RegisterCollectable(impl_->registry);
  impl_->exposer->RegisterCollectable(impl_->state);
}

Metrics::Metrics() : impl_(std::make_unique<Impl>()) {}

Metrics::~Metrics() = default;

uint16_t Metrics::port() const {
  if (!impl_->exposer) return 0;
  const std::vector<int> ports = impl_->exposer->GetListeningPorts();
  return ports.empty() ? 0 : static_cast<uint16_t>(ports.front());
}

void Metrics::request(const std::string& type, const std::string& status, double seconds, bool is_localize) {
  impl_->requests.Add({{"type", type}, {"status", status}}).Increment();
  if (is_localize) impl_->duration.Observe(seconds);
}

void Metrics::error(uint16_t code) { impl_->errors.Add({{"code", std::to_string(code)}}).Increment(); }
void Metrics::in_flight(int delta) { impl_->in_flight.Increment(delta); }
void Metrics::connections(int delta) { impl_->connections.Increment(delta); }
void Metrics::map(const std::string& name, int schema, size_t segments) {
  impl_->state->set_map(name, schema, segments);
}

std::string Metrics::text() const {
  std::vector<prometheus::MetricFamily> families = impl_->registry->Collect();
  for (prometheus::MetricFamily& f : impl_->state->Collect()) families.push_back(std::move(f));
  return prometheus::TextSerializer().Serialize(families);
}

}  // namespace server
}  // namespace segmatch
