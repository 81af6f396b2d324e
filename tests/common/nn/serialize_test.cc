// Parameter blobs: round trip, and clear errors for wrong shapes, names, groups and corruption.
#include "indrive/nn/serialize.h"

#include <gtest/gtest.h>

#include "indrive/nn/nn.h"

namespace indrive::nn {
namespace {

void build(ParamGroup& g, int units, std::uint64_t seed) {
  Rng rng(seed);
  Mlp mlp(g, "mlp", 5, {.units = units, .layers = 2, .out = 3}, rng);
  GruCell gru(g, "gru", 4, 6, rng);
}

std::string load_error(std::span<const std::uint8_t> blob, ParamGroup& g) {
  try {
    load_params(blob, g);
  } catch (const SerializationError& e) {
    return e.what();
  }
  return "";
}

TEST(SerializeTest, RoundTripRestoresEveryValue) {
  ParamGroup a("world_model"), b("world_model");
  build(a, 8, 1);
  build(b, 8, 2);
  const auto blob = save_params(a);
  load_params(blob, b);
  for (std::size_t i = 0; i < a.params().size(); ++i)
    for (std::size_t j = 0; j < a.params()[i]->value().size(); ++j)
      ASSERT_EQ(a.params()[i]->value()[j], b.params()[i]->value()[j]);
  // Several groups in one blob.
  ParamGroup c("actor"), d("actor");
  build(c, 4, 3);
  build(d, 4, 4);
  const ParamGroup* out[] = {&a, &c};
  ParamGroup* in[] = {&b, &d};
  load_params(save_params(out), in);
  EXPECT_EQ(c.params()[0]->value()[3], d.params()[0]->value()[3]);
}

TEST(SerializeTest, WrongShapeSaysWhichParameter) {
  ParamGroup a("world_model"), b("world_model");
  build(a, 8, 1);
  build(b, 9, 1);
  const std::string msg = load_error(save_params(a), b);
  EXPECT_NE(msg.find("world_model/mlp.h0.w"), std::string::npos) << msg;
  EXPECT_NE(msg.find("(5, 8)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("(5, 9)"), std::string::npos) << msg;
}

TEST(SerializeTest, FlippedByteIsDetectedAndLeavesValuesUnchanged) {
  ParamGroup a("world_model"), b("world_model");
  build(a, 8, 1);
  build(b, 8, 2);
  const float before = b.params()[0]->value()[0];
  auto blob = save_params(a);
  for (std::size_t pos : {std::size_t{5}, blob.size() / 2, blob.size() - 6}) {
    auto bad = blob;
    bad[pos] ^= 0x10;
    const std::string msg = load_error(bad, b);
    EXPECT_NE(msg.find("checksum mismatch"), std::string::npos) << msg;
  }
  EXPECT_EQ(b.params()[0]->value()[0], before);
  EXPECT_NE(load_error(std::span(blob).first(blob.size() - 100), b), "");
  EXPECT_NE(load_error({}, b).find("too short"), std::string::npos);
}

TEST(SerializeTest, WrongNamesAndGroupsAreReported) {
  ParamGroup a("world_model"), other("actor");
  build(a, 8, 1);
  build(other, 8, 1);
  EXPECT_NE(load_error(save_params(a), other).find("'world_model' where 'actor'"),
            std::string::npos);
  ParamGroup renamed("world_model");
  Rng rng(1);
  Mlp mlp(renamed, "policy", 5, {.units = 8, .layers = 2, .out = 3}, rng);
  GruCell gru(renamed, "gru", 4, 6, rng);
  const std::string msg = load_error(save_params(a), renamed);
  EXPECT_NE(msg.find("'mlp.h0.w' where the model has 'policy.h0.w'"), std::string::npos) << msg;
}

TEST(SerializeTest, ContentsNameGroupsParametersAndShapesWithoutLoading) {
  ParamGroup a("world_model"), c("actor");
  build(a, 8, 1);
  build(c, 4, 3);
  const ParamGroup* out[] = {&a, &c};
  const auto blob = save_params(out);
  EXPECT_TRUE(starts_like_blob(blob));
  const std::vector<BlobGroup> contents = blob_contents(blob);
  ASSERT_EQ(contents.size(), 2u);
  EXPECT_EQ(contents[0].name, "world_model");
  EXPECT_EQ(contents[1].name, "actor");
  ASSERT_EQ(contents[1].params.size(), c.params().size());
  for (std::size_t i = 0; i < c.params().size(); ++i) {
    EXPECT_EQ(contents[1].params[i].name, c.params()[i]->name());
    EXPECT_EQ(contents[1].params[i].shape, c.params()[i]->shape());
  }

  // A flipped byte fails the checksum; a cut blob and foreign bytes are refused by name.
  auto corrupt = blob;
  corrupt[corrupt.size() / 2] ^= 0x10;
  EXPECT_THROW(blob_contents(corrupt), SerializationError);
  const std::vector<std::uint8_t> cut(blob.begin(), blob.begin() + 10);
  EXPECT_THROW(blob_contents(cut), SerializationError);
  const std::vector<std::uint8_t> text = {'h', 'e', 'l', 'l', 'o'};
  EXPECT_FALSE(starts_like_blob(text));
  EXPECT_FALSE(starts_like_blob(std::span<const std::uint8_t>()));
}

// A filter keeps some parameters: the blob holds only those, loading sets only those, and a
// blob of another form (all parameters) is refused by the filtered load with a count.
TEST(SerializeTest, AFilterSavesAndLoadsOnlyTheParametersItKeeps) {
  ParamGroup a("world_model"), b("world_model");
  build(a, 8, 1);
  build(b, 8, 2);
  const ParamFilter keep = [](const std::string& group, const std::string& param) {
    return group == "world_model" && param.starts_with("gru.");
  };
  const ParamGroup* out[] = {&a};
  const auto blob = save_params(out, keep);
  const std::vector<BlobGroup> contents = blob_contents(blob);
  ASSERT_EQ(contents.size(), 1u);
  ASSERT_FALSE(contents[0].params.empty());
  for (const BlobParam& param : contents[0].params) EXPECT_TRUE(param.name.starts_with("gru."));
  EXPECT_LT(blob.size(), save_params(a).size());

  std::vector<std::vector<float>> before;
  for (const auto& p : b.params()) before.emplace_back(p->value().begin(), p->value().end());
  ParamGroup* in[] = {&b};
  load_params(blob, in, keep);
  for (std::size_t i = 0; i < b.params().size(); ++i) {
    const auto& p = b.params()[i];
    const std::vector<float> now(p->value().begin(), p->value().end());
    const std::vector<float> from_a(a.params()[i]->value().begin(), a.params()[i]->value().end());
    EXPECT_EQ(now, p->name().starts_with("gru.") ? from_a : before[i]) << p->name();
  }
  // Filtering the whole blob gives the same bytes as saving with the filter.
  EXPECT_EQ(filter_blob(save_params(a), keep), blob);
  // The unfiltered blob does not fit the filtered load, nor the filtered blob the plain one.
  EXPECT_THROW(load_params(save_params(a), in, keep), SerializationError);
  EXPECT_THROW(load_params(blob, b), SerializationError);
}

}  // namespace
}  // namespace indrive::nn
