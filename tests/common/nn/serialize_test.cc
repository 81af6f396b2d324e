// Parameter blobs: round trip, and clear errors for wrong shapes, names, groups and corruption.
#include "indrive/common/nn/serialize.h"

#include <gtest/gtest.h>

#include "indrive/common/nn/nn.h"

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

}  // namespace
}  // namespace indrive::nn
