// The render cluster as it runs: real gRPC servers on 127.0.0.1, real ray
// streams between workers. Its images must equal the in-process render bit
// for bit, and bad jobs must get clear errors without hurting the cluster.
#include <filesystem>
#include <fstream>

#include "client.h"
#include "convert.h"
#include "gtest/gtest.h"
#include "testing.h"
#include "transtick/image_io.h"
#include "transtick/render.h"
#include "transtick/synthetic.h"
#include "transtick/volume_io.h"

namespace transtick {
namespace {

namespace fs = std::filesystem;

// A phantom written as a raw NRRD into a fresh data directory.
std::string WritePhantom(const std::string& dir, std::array<int, 3> dims) {
  Volume v = MakeNoisyPhantom(dims, 33);
  std::ofstream f(dir + "/phantom.nrrd", std::ios::binary);
  f << "NRRD0004\ntype: float\ndimension: 3\nsizes: " << dims[0] << " " << dims[1] << " " << dims[2]
    << "\nendian: little\nencoding: raw\nspacings: 1 1 1.5\n\n";
  f.write(reinterpret_cast<const char*>(v.values.data()), v.values.size() * 4);
  return "phantom.nrrd";
}

v1::MaterialSet Materials() {
  v1::MaterialSet m;
  auto add = [&](const char* name, float lo, float hi, float op) {
    v1::Material* x = m.add_materials();
    x->set_name(name);
    x->set_min(lo);
    x->set_max(hi);
    for (float c : {0.9f, 0.7f, 0.6f}) x->add_color(c);
    x->set_opacity(op);
  };
  add("soft", 20, 45, 0.3f);
  add("hard", 45, 1000, 1.0f);
  return m;
}

Image Reference(const std::string& path, const v1::MaterialSet& m, const v1::View& view) {
  auto volume = ReadVolume(path);
  EXPECT_TRUE(volume.ok()) << volume.status();
  auto scene = Scene::ForSurfaces(*volume, *ToClassification(m));
  Vec3 extent{volume->dims[0] * volume->spacing[0], volume->dims[1] * volume->spacing[1],
              volume->dims[2] * volume->spacing[2]};
  auto camera = Camera::Create(*ToCameraSpec(view), extent);
  return testing::RenderWhole(*scene, *camera, ToRenderSettings(view));
}

class ClusterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::TempDir();
    volume_ = WritePhantom(dir_, {48, 40, 44});
  }
  v1::Job MakeJob(const std::vector<v1::View>& views) {
    v1::Job job;
    v1::Dataset* d = job.add_datasets();
    d->set_volume(volume_);
    *d->mutable_materials() = Materials();
    for (const auto& v : views) *d->add_views() = v;
    return job;
  }
  v1::View View(double az, double el, bool shadows, const std::string& out) {
    v1::View v;
    v.set_azimuth(az);
    v.set_elevation(el);
    v.set_width(64);
    v.set_height(56);
    v.set_shadows(shadows);
    v.set_output(dir_ + "/" + out);
    return v;
  }
  std::string dir_, volume_;
};

TEST_F(ClusterTest, ImagesEqualTheInProcessRender) {
  std::vector<v1::View> views = {View(45, 0, true, "a.exr"), View(0, 90, true, "b.exr"),
                                 View(20, -30, false, "c.exr")};
  std::vector<Image> want;
  for (const auto& v : views) want.push_back(Reference(dir_ + "/" + volume_, Materials(), v));
  for (int workers : {1, 2, 3, 5, 8}) {
    LocalCluster::Options o;
    o.workers = workers;
    o.data_dir = dir_;
    auto cluster = LocalCluster::Start(o);
    ASSERT_TRUE(cluster.ok()) << cluster.status();
    // Two frames in a row on the same cluster: slabs stay loaded.
    for (int round = 0; round < 2; ++round) {
      auto stats = SubmitAndWatch((*cluster)->root_address(), MakeJob(views), WatchOptions{});
      ASSERT_TRUE(stats.ok()) << stats.status();
      ASSERT_EQ(stats->size(), views.size());
      EXPECT_EQ(stats->front().workers_size(), workers);
      for (size_t i = 0; i < views.size(); ++i) {
        auto got = ReadImage(views[i].output());
        ASSERT_TRUE(got.ok()) << got.status();
        EXPECT_EQ(got->rgb, want[i].rgb) << workers << " workers, view " << i;
      }
    }
  }
}

TEST_F(ClusterTest, BadJobsGetClearErrorsAndTheClusterGoesOn) {
  LocalCluster::Options o;
  o.workers = 2;
  o.data_dir = dir_;
  auto cluster = LocalCluster::Start(o);
  ASSERT_TRUE(cluster.ok()) << cluster.status();
  const std::string root = (*cluster)->root_address();
  auto expect_error = [&](v1::Job job, const std::string& text) {
    auto r = SubmitAndWatch(root, job, WatchOptions{});
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find(text), std::string::npos) << r.status().message();
  };
  v1::Job missing = MakeJob({View(0, 0, true, "x.png")});
  missing.mutable_datasets(0)->set_volume("nope.nrrd");
  expect_error(missing, "nope.nrrd");
  v1::Job outside = MakeJob({View(0, 0, true, "x.png")});
  outside.mutable_datasets(0)->set_volume("../../etc/passwd");
  expect_error(outside, "outside the data directory");
  v1::Job zero = MakeJob({View(0, 0, true, "x.png")});
  zero.mutable_datasets(0)->mutable_views(0)->set_width(0);
  expect_error(zero, "0x56");
  v1::Job huge = MakeJob({View(0, 0, true, "x.png")});
  huge.mutable_datasets(0)->mutable_views(0)->set_width(100000);
  expect_error(huge, "100000x56");
  // A file in the data directory that is not a volume fails the job.
  std::ofstream(dir_ + "/junk.nrrd") << "NRRD0004\ntype: float\n";
  v1::Job junk = MakeJob({View(0, 0, true, "x.png")});
  junk.mutable_datasets(0)->set_volume("junk.nrrd");
  expect_error(junk, "junk.nrrd");
  // And the next good job still renders.
  v1::View good = View(30, 10, true, "good.png");
  auto ok = SubmitAndWatch(root, MakeJob({good}), WatchOptions{});
  ASSERT_TRUE(ok.ok()) << ok.status();
  EXPECT_TRUE(fs::exists(good.output()));
}

TEST_F(ClusterTest, StressEveryRayCrossesEverySlab) {
  // Looking along Y with 8 workers: every ray crosses every slab.
  LocalCluster::Options o;
  o.workers = 8;
  o.data_dir = dir_;
  auto cluster = LocalCluster::Start(o);
  ASSERT_TRUE(cluster.ok()) << cluster.status();
  v1::View v = View(0, 90, true, "top.exr");
  v.set_width(96);
  v.set_height(96);
  Image want = Reference(dir_ + "/" + volume_, Materials(), v);
  for (int frame = 0; frame < 4; ++frame) {
    auto stats = SubmitAndWatch((*cluster)->root_address(), MakeJob({v}), WatchOptions{});
    ASSERT_TRUE(stats.ok()) << stats.status();
    uint64_t sent = 0;
    for (const auto& w : stats->front().workers()) sent += w.rays_sent();
    EXPECT_GT(sent, 96u * 96u);
    EXPECT_EQ(ReadImage(v.output())->rgb, want.rgb);
  }
}

}  // namespace
}  // namespace transtick
