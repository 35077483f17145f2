// Counter-based random numbers keyed by (seed, tile, sample, dimension): Philox4x32-10 from
// Random123 (Salmon et al., SC'11). A sample's numbers depend only on these keys, so a job's output
// is identical for any number of ranks and threads, and one failing sample can be replayed from
// its seed and indices.
#pragma once
#include <Random123/philox.h>

#include <cstdint>

namespace mbsdf {

class Sampler {
 public:
  Sampler(uint64_t seed, uint32_t tile, uint64_t sample, uint32_t stream = 0)
      : key_{{uint32_t(seed), uint32_t(seed >> 32)}},
        ctr_{{tile, uint32_t(sample), uint32_t(sample >> 32) ^ (stream << 16), 0}} {}

  // Next uniform double in [0, 1). One Philox block (one "dimension" of the counter) gives two.
  double get1D() {
    if (have_ == 0) refill();
    uint64_t bits = (uint64_t(buf_[2 * (2 - have_)]) << 32) | buf_[2 * (2 - have_) + 1];
    --have_;
    return double(bits >> 11) * 0x1.0p-53;
  }
  // Jump to block `dim`, whose two numbers are the sample's numbers 2·dim and 2·dim + 1 whatever
  // came before (skipping a block that is not needed costs nothing).
  void setDimension(uint32_t dim) {
    ctr_.v[3] = dim;
    have_ = 0;
  }
  uint32_t dimension() const { return ctr_.v[3]; }
  // Where the sampler stands, in five bytes: the block it draws next, and whether the second
  // number of the block before it is still to be drawn. resume() continues from there a sampler
  // made with the same seed, tile, sample and stream: it draws the numbers this one would draw next.
  uint32_t nextBlock() const { return ctr_.v[3]; }
  bool secondLeft() const { return have_ == 1; }
  void resume(uint32_t nextBlock, bool secondLeft) {
    ctr_.v[3] = secondLeft ? nextBlock - 1 : nextBlock;
    have_ = 0;
    if (secondLeft) {
      refill();
      have_ = 1;
    }
  }

 private:
  void refill() {
    auto r = r123::Philox4x32()(ctr_, key_);
    buf_[0] = r.v[0];
    buf_[1] = r.v[1];
    buf_[2] = r.v[2];
    buf_[3] = r.v[3];
    ctr_.v[3]++;
    have_ = 2;
  }
  r123::Philox4x32::key_type key_;
  r123::Philox4x32::ctr_type ctr_;
  uint32_t buf_[4] = {0, 0, 0, 0};
  int have_ = 0;
};

}  // namespace mbsdf
