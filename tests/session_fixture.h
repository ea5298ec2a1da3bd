// What the session tests and the web gateway tests share: a noisy phantom
// in a data directory, its materials and cameras, and the in-process render
// every frame of a session must equal.
#ifndef TRANSTICK_TESTS_SESSION_FIXTURE_H_
#define TRANSTICK_TESTS_SESSION_FIXTURE_H_

#include <fstream>
#include <memory>
#include <string>

#include "cluster.pb.h"
#include "convert.h"
#include "gtest/gtest.h"
#include "local_cluster.h"
#include "testing.h"
#include "transtick/camera.h"
#include "transtick/scene.h"
#include "transtick/synthetic.h"
#include "transtick/volume_io.h"

namespace transtick::testing {

// One material from `lo` up.
inline v1::MaterialSet Materials(float lo) {
  v1::MaterialSet m;
  v1::Material* x = m.add_materials();
  x->set_name("hard");
  x->set_min(lo);
  x->set_max(1000);
  for (float c : {0.9f, 0.7f, 0.6f}) x->add_color(c);
  return m;
}

inline v1::View Camera(double azimuth, int width = 40, int height = 32) {
  v1::View v;
  v.set_azimuth(azimuth);
  v.set_elevation(25);
  v.set_width(width);
  v.set_height(height);
  v.set_shadows(true);
  return v;
}

// Writes the phantom as dir/p.nrrd (36x32x40 floats, spacing 1 1 1.25).
inline void WritePhantom(const std::string& dir) {
  Volume v = MakeNoisyPhantom({36, 32, 40}, 7);
  std::ofstream f(dir + "/p.nrrd", std::ios::binary);
  f << "NRRD0004\ntype: float\ndimension: 3\nsizes: 36 32 40\nendian: little\nencoding: raw\n"
       "spacings: 1 1 1.25\n\n";
  f.write(reinterpret_cast<const char*>(v.values.data()), v.values.size() * 4);
}

// WritePhantom(dir), and an embedded cluster of 2 workers serving it; null
// (with a test failure) when it does not start.
inline std::unique_ptr<LocalCluster> PhantomCluster(const std::string& dir) {
  WritePhantom(dir);
  LocalCluster::Options o;
  o.workers = 2;
  o.data_dir = dir;
  auto c = LocalCluster::Start(o);
  EXPECT_TRUE(c.ok()) << c.status();
  return c.ok() ? *std::move(c) : nullptr;
}

// The in-process render of dir/p.nrrd with Materials(lo) from `view`.
inline Image PhantomReference(const std::string& dir, const v1::View& view, float lo = 45) {
  auto volume = ReadVolume(dir + "/p.nrrd");
  EXPECT_TRUE(volume.ok());
  auto scene = Scene::ForSurfaces(*volume, *ToClassification(Materials(lo)));
  Vec3 extent{volume->dims[0] * volume->spacing[0], volume->dims[1] * volume->spacing[1],
              volume->dims[2] * volume->spacing[2]};
  auto camera = Camera::Create(*ToCameraSpec(view), extent);
  return RenderWhole(*scene, *camera, ToRenderSettings(view));
}

}  // namespace transtick::testing

#endif  // TRANSTICK_TESTS_SESSION_FIXTURE_H_
