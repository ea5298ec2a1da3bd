#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "convert.h"
#include "gtest/gtest.h"
#include "testing.h"

namespace transtick {
namespace {

std::string Write(const std::string& dir, const std::string& name, const std::string& text) {
  std::string path = dir + "/" + name;
  std::ofstream(path) << text;
  return path;
}

TEST(ApiTest, LoadsMaterialsWithDefaults) {
  std::string dir = testing::TempDir();
  auto c = LoadMaterials(Write(dir, "m.json", R"({"materials":[
      {"name":"skin","min":1300,"max":1900,"color":[0.9,0.7,0.6],"opacity":0.3},
      {"name":"bone","min":1900,"max":4000,"color":[1,1,1],"specular":0.5}]})"));
  ASSERT_TRUE(c.ok()) << c.status();
  ASSERT_EQ(c->materials.size(), 2u);
  EXPECT_FLOAT_EQ(c->materials[0].opacity, 0.3f);
  EXPECT_FLOAT_EQ(c->materials[1].opacity, 1.0f);  // absent means opaque
  EXPECT_FLOAT_EQ(c->materials[1].specular, 0.5f);
  EXPECT_EQ(c->Classify(1500), 1);
  EXPECT_EQ(c->Classify(1900), 2);
  EXPECT_EQ(c->Classify(100), 0);
}

// Balancing, cut rules and projections are enums; job files keep the
// spelling they had as strings.
TEST(ApiTest, EnumsReadAsJobFilesWroteThem) {
  for (const char* balance : {"test-rays", "TEST_RAYS", "Test-Rays"}) {
    v1::Job job;
    const std::string json = absl::StrCat(R"({"name":"j","balance":")", balance,
                                          R"(","balance_rule":"paper","datasets":[{"volume":"v",)",
                                          R"("views":[{"projection":"orthographic",)",
                                          R"("balance":"previous-frame"},{"width":3}]}]})");
    ASSERT_TRUE(ParseJson(json, "job.json", &job).ok()) << balance;
    EXPECT_EQ(job.balance(), v1::TEST_RAYS);
    EXPECT_EQ(job.balance_rule(), v1::PAPER);
    EXPECT_EQ(job.datasets(0).views(0).projection(), v1::ORTHOGRAPHIC);
    EXPECT_EQ(job.datasets(0).views(0).balance(), v1::PREVIOUS_FRAME);
    EXPECT_EQ(job.datasets(0).views(1).width(), 3);
    EXPECT_EQ(*EffectiveBalance(job, job.datasets(0).views(0)), v1::PREVIOUS_FRAME);
    EXPECT_EQ(*EffectiveBalance(job, job.datasets(0).views(1)), v1::TEST_RAYS);
  }
  v1::Job job;
  EXPECT_EQ(*EffectiveBalance(job, v1::View()), v1::OFF) << "neither says: off";
  // A wrong name is still an error naming the file.
  absl::Status bad = ParseJson(R"({"balance":"magic"})", "job.json", &job);
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("job.json"), std::string::npos) << bad;
  // Flags name the values that exist.
  auto flag = ParseEnum<v1::BalanceMode>("magic", "--balance");
  ASSERT_FALSE(flag.ok());
  EXPECT_EQ(flag.status().message(),
            "--balance 'magic' is not one of off, test-rays, previous-frame");
  EXPECT_EQ(*ParseEnum<v1::BalanceMode>("", "--balance"), v1::BALANCE_DEFAULT);
  EXPECT_EQ(*ParseEnum<v1::Projection>("orthographic", "--projection"), v1::ORTHOGRAPHIC);
  EXPECT_FALSE(ParseEnum<v1::Projection>("projection-default", "--projection").ok())
      << "the 0 value is not a name users write";
  EXPECT_EQ(EnumName(v1::PREVIOUS_FRAME), "previous-frame");
  EXPECT_EQ(EnumName(static_cast<v1::BalanceMode>(77)), "77");
  // A value this build does not know (from a newer client) is refused.
  v1::View future;
  future.set_balance(static_cast<v1::BalanceMode>(9));
  EXPECT_FALSE(EffectiveBalance(job, future).ok());
  future.set_projection(static_cast<v1::Projection>(9));
  EXPECT_FALSE(ToCameraSpec(future).ok());
  EXPECT_FALSE(ToBalanceRule(static_cast<v1::BalanceRule>(9)).ok());
}

TEST(ApiTest, ImageEncodingsInJobFilesAndChunks) {
  for (const char* name : {"rgb8", "RGB8", "float32"}) {
    v1::Job job;
    ASSERT_TRUE(
        ParseJson(absl::StrCat(R"({"image_encoding":")", name, R"("})"), "job.json", &job).ok())
        << name;
    EXPECT_EQ(job.image_encoding(), std::string(name) == "float32" ? v1::FLOAT32 : v1::RGB8);
  }
  EXPECT_EQ(*ToImageEncoding(v1::IMAGE_ENCODING_DEFAULT, "x"), v1::FLOAT32);
  EXPECT_EQ(*ToImageEncoding(v1::RGB8, "x"), v1::RGB8);
  auto bad = ToImageEncoding(static_cast<v1::ImageEncoding>(3), "job: image_encoding");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message(), "job: image_encoding 3 is not an encoding (float32 or rgb8)");
  // A chunk's rows fit one encoding exactly, and only in its own field.
  v1::ImageChunk c;
  c.set_width(5);
  c.set_height(9);
  c.set_row_begin(2);
  c.set_row_end(4);
  c.set_rgb(std::string(2 * 5 * 12, '\0'));
  EXPECT_TRUE(ChunkBytesFit(c, v1::FLOAT32));
  EXPECT_FALSE(ChunkBytesFit(c, v1::RGB8));
  EXPECT_EQ(*ChunkEncoding(c), v1::FLOAT32);
  c.set_rgb8(std::string(2 * 5 * 3, '\0'));
  EXPECT_FALSE(ChunkBytesFit(c, v1::FLOAT32)) << "both fields set";
  EXPECT_FALSE(ChunkBytesFit(c, v1::RGB8)) << "both fields set";
  EXPECT_FALSE(ChunkEncoding(c).ok());
  c.clear_rgb();
  EXPECT_EQ(*ChunkEncoding(c), v1::RGB8);
  EXPECT_EQ(ChunkBytes(c, v1::RGB8).size(), 30u);
  c.set_row_end(1);  // rows backwards
  EXPECT_FALSE(ChunkEncoding(c).ok());
  c.set_row_end(4);
  c.set_width(-5);
  EXPECT_FALSE(ChunkEncoding(c).ok());
  c.set_width(5);
  c.mutable_rgb8()->push_back('\1');
  auto why = ChunkEncoding(c);
  ASSERT_FALSE(why.ok());
  EXPECT_NE(why.status().message().find("31 of rgb8"), std::string::npos) << why.status();
}

// A preset takes a surface model as a materials file does; dvr has none.
TEST(ApiTest, PresetsTakeASurfaceModel) {
  for (const auto& [name, expect] : std::vector<std::pair<std::string, v1::SurfaceModel>>{
           {"", v1::SURFACE_DEFAULT}, {"voxel", v1::VOXEL}, {"smooth", v1::SMOOTH}}) {
    v1::Dataset ds;
    const std::string surface = name.empty() ? "" : absl::StrCat(R"(,"surface":")", name, R"(")");
    ASSERT_TRUE(
        ParseJson(absl::StrCat(R"({"volume":"v","preset":{"name":"ct-bone")", surface, "}}"),
                  "job.json", &ds)
            .ok())
        << name;
    auto resolved = ResolvePreset(ds, {-1000, 3000});
    ASSERT_TRUE(resolved.ok()) << resolved.status();
    ASSERT_TRUE(resolved->has_materials());
    EXPECT_EQ(resolved->materials().surface(), expect) << name;
    auto c = ToClassification(resolved->materials());
    ASSERT_TRUE(c.ok()) << c.status();
    EXPECT_EQ(c->surface, expect == v1::VOXEL ? SurfaceModel::kVoxel : SurfaceModel::kSmooth);
  }
  v1::Dataset dvr;
  dvr.mutable_preset()->set_name("ct-bone");
  dvr.mutable_preset()->set_mode(v1::DVR);
  dvr.mutable_preset()->set_surface(v1::VOXEL);
  auto refused = ResolvePreset(dvr, {0, 1});
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().message(),
            "preset 'ct-bone': a surface model is for surfaces mode, not dvr");
  // A value this build does not know is refused where the materials are.
  v1::Dataset future;
  future.mutable_preset()->set_name("ct-bone");
  future.mutable_preset()->set_surface(static_cast<v1::SurfaceModel>(9));
  auto resolved = ResolvePreset(future, {0, 1});
  ASSERT_TRUE(resolved.ok());
  EXPECT_FALSE(ToClassification(resolved->materials()).ok());
}

TEST(ApiTest, BadMaterialsNameTheProblem) {
  std::string dir = testing::TempDir();
  struct Case {
    const char* json;
    const char* expect;
  } cases[] = {
      {R"({"materials":[{"name":"a","min":1,"max":2,"color":[1,1]}]})", "color has 2"},
      {R"({"materials":[{"name":"a","min":3,"max":2,"color":[1,1,1]}]})", "interval"},
      {R"({"materials":[{"name":"a","min":1,"max":2,"color":[1,1,1],"opacity":2}]})", "opacity"},
      {R"({"materials":[{"name":"a","min":1,"max":2,"colour":[1,1,1]}]})", "colour"},
      {R"({"materials":[)", "m.json"},
      {R"({"materials":[]})", "none given"},
      {R"({"materials":[{"min":1,"max":2,"color":[1,1,1]}]})", "name is empty"},
  };
  for (const Case& c : cases) {
    auto r = LoadMaterials(Write(dir, "m.json", c.json));
    ASSERT_FALSE(r.ok()) << c.json;
    EXPECT_NE(r.status().message().find(c.expect), std::string::npos)
        << c.json << " -> " << r.status().message();
    EXPECT_NE(r.status().message().find("m.json"), std::string::npos) << r.status().message();
  }
  EXPECT_EQ(LoadMaterials(dir + "/missing.json").status().code(), absl::StatusCode::kNotFound);
}

TEST(ApiTest, TransferFunctions) {
  std::string dir = testing::TempDir();
  auto tf = LoadTransferFunction(Write(dir, "t.json", R"({"points":[
      {"value":0,"rgba":[0,0,0,0]},{"value":100,"rgba":[1,0.5,0,0.5]}],"shading":false})"));
  ASSERT_TRUE(tf.ok()) << tf.status();
  EXPECT_FALSE(tf->shading);
  auto mid = tf->Evaluate(50);
  EXPECT_FLOAT_EQ(mid[0], 0.5f);
  EXPECT_FLOAT_EQ(mid[3], 0.25f);
  EXPECT_FLOAT_EQ(tf->Evaluate(1000)[3], 0.5f);
  auto bad = LoadTransferFunction(Write(dir, "t.json", R"({"points":[
      {"value":10,"rgba":[0,0,0,0]},{"value":5,"rgba":[1,1,1,1]}]})"));
  EXPECT_NE(bad.status().message().find("does not increase"), std::string::npos);
}

// The shading coefficients of a transfer function are bounded as a
// material's are. Unchecked, a job with "shininess": "NaN" or ambient and
// diffuse near FLT_MAX was accepted, and every frame then failed at the
// display on NaN or infinite deposits (found by job_fuzzer).
TEST(ApiTest, TransferFunctionShadingIsBounded) {
  std::string dir = testing::TempDir();
  const std::string points = R"("points":[{"value":0,"rgba":[0,0,0,0]},
      {"value":100,"rgba":[1,0.5,0,0.5]}])";
  struct Case {
    const char* fields;
    const char* expect;
  } cases[] = {
      {R"("shininess":"NaN")", "shininess nan"},
      {R"("shininess":-50)", "shininess -50"},
      {R"("ambient":3e38,"diffuse":3e38)", "shading coefficient 3e+38"},
      {R"("specular":-1)", "shading coefficient -1"},
  };
  for (const Case& c : cases) {
    auto tf = LoadTransferFunction(
        Write(dir, "t.json", "{" + points + "," + std::string(c.fields) + "}"));
    ASSERT_FALSE(tf.ok()) << c.fields;
    EXPECT_NE(tf.status().message().find(c.expect), std::string::npos)
        << c.fields << " -> " << tf.status().message();
  }
  auto shaded = LoadTransferFunction(Write(dir, "t.json", "{" + points + R"(,"ambient":4,
      "diffuse":0,"specular":4,"shininess":1000})"));
  EXPECT_TRUE(shaded.ok()) << shaded.status();
}

}  // namespace
}  // namespace transtick
