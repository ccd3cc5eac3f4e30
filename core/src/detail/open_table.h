// The core's one hash table: open addressing with linear probing over a power-of-two array of
// slots, the home slot by Fibonacci hashing (the key times 2^64 / phi, its top bits). The
// slot layout is the user's: FlatHashMap (cell key -> index), the voxel filter's voxel sums
// and the voxel accumulator's per-tile voxels each keep what they need in one cache-friendly
// struct, and share the probing, the sizing and the rebuild. No erase: users that remove keep
// dead slots and rebuild without them. Private to the core.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace segmatch::detail {

// Slot: a trivially copyable struct with a `key` member (an unsigned integer), a static
// `Slot free_slot()` and `bool is_free() const`.
template <typename Slot>
class OpenTable {
 public:
  using Key = decltype(Slot::key);
  static constexpr size_t kNone = ~size_t{0};

  explicit OpenTable(size_t expected = 0) { allocate(expected); }

  size_t capacity() const { return slots_.size(); }
  size_t used() const { return used_; }  // claimed slots, dead ones included
  Slot& operator[](size_t s) { return slots_[s]; }
  const Slot& operator[](size_t s) const { return slots_[s]; }

  size_t home(Key key) const {
    return static_cast<size_t>((static_cast<uint64_t>(key) * 0x9E3779B97F4A7C15ull) >> shift_);
  }
  void prefetch(Key key) const { __builtin_prefetch(&slots_[home(key)]); }

  // The slot holding `key`, or kNone.
  size_t find(Key key) const {
    for (size_t s = home(key);; s = (s + 1) & mask_) {
      if (slots_[s].is_free()) return kNone;
      if (slots_[s].key == key) return s;
    }
  }

  // The slot holding `key`, claimed (set to free_slot() with this key) if absent; *claimed tells
  // which. kNone, with nothing changed, when claiming would fill the table beyond 70 %: the
  // user rebuilds (moving what it keeps beside the slots) and asks again.
  size_t find_or_claim(Key key, bool* claimed) {
    for (size_t s = home(key);; s = (s + 1) & mask_) {
      Slot& slot = slots_[s];
      if (slot.is_free()) {
        if (10 * (used_ + 1) > 7 * slots_.size()) return kNone;
        slot = Slot::free_slot();
        slot.key = key;
        ++used_;
        *claimed = true;
        return s;
      }
      if (slot.key == key) {
        *claimed = false;
        return s;
      }
    }
  }

  // A table sized for `expected` slots (at most half full) holding the slots keep(slot)
  // admits, in their new homes; moved(old_index, new_index) after each, for data kept in
  // parallel arrays.
  template <typename Keep, typename Moved>
  void rebuild(size_t expected, Keep&& keep, Moved&& moved) {
    const std::vector<Slot> old = std::move(slots_);
    allocate(expected);
    for (size_t o = 0; o < old.size(); ++o) {
      if (old[o].is_free() || !keep(old[o])) continue;
      size_t s = home(old[o].key);
      while (!slots_[s].is_free()) s = (s + 1) & mask_;
      slots_[s] = old[o];
      ++used_;
      moved(o, s);
    }
  }
  void grow() {
    rebuild(
        slots_.size(), [](const Slot&) { return true; }, [](size_t, size_t) {});
  }

 private:
  void allocate(size_t expected) {
    size_t capacity = 16;
    while (capacity < 2 * expected) capacity <<= 1;
    slots_.assign(capacity, Slot::free_slot());
    mask_ = capacity - 1;
    shift_ = 64;
    while ((size_t{1} << (64 - shift_)) < capacity) --shift_;
    used_ = 0;
  }

  std::vector<Slot> slots_;
  size_t mask_ = 0, used_ = 0;
  int shift_ = 60;
};

}  // namespace segmatch::detail
