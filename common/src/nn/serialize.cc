// Parameter blobs: names, shapes and values of parameter groups with a trailing CRC-32.
#include "indrive/common/nn/serialize.h"

#include <algorithm>

#include "bytes.h"

namespace indrive::nn {

namespace {
constexpr std::uint32_t kMagic = 0x504e4e49;  // "INNP"
constexpr std::uint32_t kVersion = 1;
}  // namespace

std::vector<std::uint8_t> save_params(std::span<const ParamGroup* const> groups) {
  detail::ByteWriter w;
  w.u32(kMagic);
  w.u32(kVersion);
  w.u32(static_cast<std::uint32_t>(groups.size()));
  for (const ParamGroup* g : groups) {
    w.str(g->name());
    w.u32(static_cast<std::uint32_t>(g->params().size()));
    for (const auto& p : g->params()) {
      w.str(p->name());
      w.u32(static_cast<std::uint32_t>(p->shape().rank));
      for (int d = 0; d < p->shape().rank; ++d) w.i64(p->shape().dims[d]);
      w.floats(p->value());
    }
  }
  return w.finish();
}

std::vector<std::uint8_t> save_params(const ParamGroup& group) {
  const ParamGroup* groups[] = {&group};
  return save_params(groups);
}

void load_params(std::span<const std::uint8_t> blob, std::span<ParamGroup* const> groups) {
  detail::ByteReader r(blob, "parameter blob");
  if (r.u32() != kMagic)
    throw SerializationError("parameter blob: bad magic; this is not a parameter blob");
  const std::uint32_t version = r.u32();
  if (version != kVersion)
    throw SerializationError("parameter blob: version " + std::to_string(version) +
                             ", this build reads version " + std::to_string(kVersion));
  const std::uint32_t count = r.u32();
  if (count != groups.size())
    throw SerializationError("parameter blob holds " + std::to_string(count) +
                             " groups, expected " + std::to_string(groups.size()));
  // Read everything into staging buffers first, so a failure leaves the groups unchanged.
  std::vector<std::vector<float>> staged;
  for (const ParamGroup* g : groups) {
    const std::string gname = r.str();
    if (gname != g->name())
      throw SerializationError("parameter blob: group '" + gname + "' where '" + g->name() +
                               "' was expected");
    const std::uint32_t n = r.u32();
    if (n != g->params().size())
      throw SerializationError("parameter blob: group '" + gname + "' has " + std::to_string(n) +
                               " parameters, the model has " + std::to_string(g->params().size()) +
                               "; the model architecture (preset) differs");
    for (const auto& p : g->params()) {
      const std::string pname = r.str();
      if (pname != p->name())
        throw SerializationError("parameter blob: group '" + gname + "' has parameter '" + pname +
                                 "' where the model has '" + p->name() + "'");
      const std::uint32_t rank = r.u32();
      if (rank > static_cast<std::uint32_t>(kMaxRank))
        throw SerializationError("parameter blob: '" + gname + "/" + pname + "' has rank " +
                                 std::to_string(rank));
      Shape s;
      s.rank = static_cast<int>(rank);
      for (std::uint32_t d = 0; d < rank; ++d) s.dims[d] = r.i64();
      if (s != p->shape())
        throw SerializationError("parameter blob: '" + gname + "/" + pname + "' has shape " +
                                 s.str() + " but the model expects " + p->shape().str() +
                                 "; the model architecture (preset) differs");
      staged.emplace_back(static_cast<std::size_t>(p->numel()));
      r.floats(staged.back());
    }
  }
  if (!r.done())
    throw SerializationError("parameter blob: trailing bytes after the last parameter");
  std::size_t i = 0;
  for (ParamGroup* g : groups)
    for (const auto& p : g->params()) {
      std::copy(staged[i].begin(), staged[i].end(), p->value().begin());
      ++i;
    }
}

void load_params(std::span<const std::uint8_t> blob, ParamGroup& group) {
  ParamGroup* groups[] = {&group};
  load_params(blob, groups);
}

}  // namespace indrive::nn
