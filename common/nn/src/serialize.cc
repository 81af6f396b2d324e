// Parameter blobs: names, shapes and values of parameter groups with a trailing CRC-32.
#include "indrive/nn/serialize.h"

#include <algorithm>
#include <cstring>

#include "bytes.h"

namespace indrive::nn {

namespace {
constexpr std::uint32_t kMagic = 0x504e4e49;  // "INNP"
constexpr std::uint32_t kVersion = 1;

// Reads magic and version and returns the group count.
std::uint32_t read_prelude(detail::ByteReader& r) {
  if (r.u32() != kMagic)
    throw SerializationError("parameter blob: bad magic; this is not a parameter blob");
  const std::uint32_t version = r.u32();
  if (version != kVersion)
    throw SerializationError("parameter blob: version " + std::to_string(version) +
                             ", this build reads version " + std::to_string(kVersion));
  return r.u32();
}

// The parameters of a group that `keep` keeps (all when keep is empty), in the group's order.
std::vector<Parameter*> kept_params(const ParamGroup& g, const ParamFilter& keep) {
  std::vector<Parameter*> out;
  out.reserve(g.params().size());
  for (const auto& p : g.params())
    if (!keep || keep(g.name(), p->name())) out.push_back(p.get());
  return out;
}

// Reads a parameter's rank and dimensions, checked against what a Shape can hold.
Shape read_shape(detail::ByteReader& r, const std::string& where) {
  const std::uint32_t rank = r.u32();
  if (rank > static_cast<std::uint32_t>(kMaxRank))
    throw SerializationError("parameter blob: '" + where + "' has rank " + std::to_string(rank));
  Shape s;
  s.rank = static_cast<int>(rank);
  for (std::uint32_t d = 0; d < rank; ++d) s.dims[d] = r.i64();
  return s;
}
}  // namespace

std::vector<std::uint8_t> save_params(std::span<const ParamGroup* const> groups) {
  return save_params(groups, nullptr);
}

std::vector<std::uint8_t> save_params(std::span<const ParamGroup* const> groups,
                                      const ParamFilter& keep) {
  detail::ByteWriter w;
  w.u32(kMagic);
  w.u32(kVersion);
  w.u32(static_cast<std::uint32_t>(groups.size()));
  for (const ParamGroup* g : groups) {
    const std::vector<Parameter*> params = kept_params(*g, keep);
    w.str(g->name());
    w.u32(static_cast<std::uint32_t>(params.size()));
    for (const Parameter* p : params) {
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
  load_params(blob, groups, nullptr);
}

void load_params(std::span<const std::uint8_t> blob, std::span<ParamGroup* const> groups,
                 const ParamFilter& keep) {
  detail::ByteReader r(blob, "parameter blob");
  const std::uint32_t count = read_prelude(r);
  if (count != groups.size())
    throw SerializationError("parameter blob holds " + std::to_string(count) +
                             " groups, expected " + std::to_string(groups.size()));
  // Read everything into staging buffers first, so a failure leaves the groups unchanged.
  std::vector<std::vector<float>> staged;
  std::vector<Parameter*> targets;
  for (ParamGroup* g : groups) {
    const std::string gname = r.str();
    if (gname != g->name())
      throw SerializationError("parameter blob: group '" + gname + "' where '" + g->name() +
                               "' was expected");
    const std::vector<Parameter*> params = kept_params(*g, keep);
    const std::uint32_t n = r.u32();
    if (n != params.size())
      throw SerializationError("parameter blob: group '" + gname + "' has " + std::to_string(n) +
                               " parameters, the model has " + std::to_string(params.size()) +
                               (keep ? " to load" : "") +
                               "; the model architecture (preset) differs");
    for (Parameter* p : params) {
      const std::string pname = r.str();
      if (pname != p->name())
        throw SerializationError("parameter blob: group '" + gname + "' has parameter '" + pname +
                                 "' where the model has '" + p->name() + "'");
      const Shape s = read_shape(r, gname + "/" + pname);
      if (s != p->shape())
        throw SerializationError("parameter blob: '" + gname + "/" + pname + "' has shape " +
                                 s.str() + " but the model expects " + p->shape().str() +
                                 "; the model architecture (preset) differs");
      staged.emplace_back(static_cast<std::size_t>(p->numel()));
      r.floats(staged.back());
      targets.push_back(p);
    }
  }
  if (!r.done())
    throw SerializationError("parameter blob: trailing bytes after the last parameter");
  for (std::size_t i = 0; i < targets.size(); ++i)
    std::copy(staged[i].begin(), staged[i].end(), targets[i]->value().begin());
}

void load_params(std::span<const std::uint8_t> blob, ParamGroup& group) {
  ParamGroup* groups[] = {&group};
  load_params(blob, groups);
}

bool starts_like_blob(std::span<const std::uint8_t> bytes) {
  std::uint32_t first = 0;
  if (bytes.size() < sizeof(first)) return false;
  std::memcpy(&first, bytes.data(), sizeof(first));
  return first == kMagic;
}

std::vector<BlobGroup> blob_contents(std::span<const std::uint8_t> blob) {
  detail::ByteReader r(blob, "parameter blob");
  const std::uint32_t count = read_prelude(r);
  std::vector<BlobGroup> groups;
  for (std::uint32_t g = 0; g < count; ++g) {
    BlobGroup group{.name = r.str(), .params = {}};
    const std::uint32_t n = r.u32();
    for (std::uint32_t p = 0; p < n; ++p) {
      BlobParam param{.name = r.str(), .shape = {}};
      param.shape = read_shape(r, group.name + "/" + param.name);
      std::uint64_t numel = 1;
      for (int d = 0; d < param.shape.rank; ++d) {
        const std::int64_t dim = param.shape.dims[d];
        // A dimension past the blob's own size cannot be real; checking it keeps numel finite.
        if (dim < 0 || static_cast<std::uint64_t>(dim) > blob.size())
          throw SerializationError("parameter blob: '" + group.name + "/" + param.name +
                                   "' has dimension " + std::to_string(dim));
        numel *= static_cast<std::uint64_t>(dim);
        if (numel > blob.size())
          throw SerializationError("parameter blob: '" + group.name + "/" + param.name +
                                   "' has more values than the blob has bytes; it is truncated");
      }
      r.skip(numel * sizeof(float));
      group.params.push_back(std::move(param));
    }
    groups.push_back(std::move(group));
  }
  if (!r.done())
    throw SerializationError("parameter blob: trailing bytes after the last parameter");
  return groups;
}

std::vector<std::uint8_t> filter_blob(std::span<const std::uint8_t> blob, const ParamFilter& keep) {
  const std::vector<BlobGroup> contents = blob_contents(blob);  // checks every size first
  detail::ByteReader r(blob, "parameter blob");
  read_prelude(r);
  detail::ByteWriter w;
  w.u32(kMagic);
  w.u32(kVersion);
  w.u32(static_cast<std::uint32_t>(contents.size()));
  std::vector<float> values;
  for (const BlobGroup& group : contents) {
    r.str();
    r.u32();
    const auto kept = std::count_if(group.params.begin(), group.params.end(),
                                    [&](const BlobParam& p) { return keep(group.name, p.name); });
    w.str(group.name);
    w.u32(static_cast<std::uint32_t>(kept));
    for (const BlobParam& param : group.params) {
      r.str();
      read_shape(r, group.name + "/" + param.name);
      values.resize(static_cast<std::size_t>(param.shape.numel()));
      r.floats(values);
      if (!keep(group.name, param.name)) continue;
      w.str(param.name);
      w.u32(static_cast<std::uint32_t>(param.shape.rank));
      for (int d = 0; d < param.shape.rank; ++d) w.i64(param.shape.dims[d]);
      w.floats(values);
    }
  }
  return w.finish();
}

}  // namespace indrive::nn
