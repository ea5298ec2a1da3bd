#include "convert.h"

#include <google/protobuf/util/json_util.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "absl/strings/str_cat.h"

namespace transtick {

absl::StatusOr<std::string> ReadTextFile(const std::string& path, size_t max_bytes) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  std::string text;
  char buf[65536];
  while (in.read(buf, sizeof buf) || in.gcount() > 0) {
    text.append(buf, static_cast<size_t>(in.gcount()));
    if (text.size() > max_bytes) {
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": larger than ", max_bytes, " bytes; not a job or settings file"));
    }
  }
  return text;
}

absl::Status ParseJson(std::string_view json, const std::string& source,
                       google::protobuf::Message* message) {
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = false;
  auto status = google::protobuf::util::JsonStringToMessage(
      google::protobuf::StringPiece(json.data(), json.size()), message, options);
  if (!status.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": not a valid ",
                                                   message->GetDescriptor()->name(), ": ",
                                                   std::string(status.message())));
  }
  return absl::OkStatus();
}

absl::StatusOr<Classification> ToClassification(const v1::MaterialSet& set) {
  Classification c;
  for (int i = 0; i < set.materials_size(); ++i) {
    const v1::Material& pm = set.materials(i);
    Material m;
    m.name = pm.name();
    m.min = pm.min();
    m.max = pm.max();
    if (pm.color_size() != 3) {
      return absl::InvalidArgumentError(absl::StrCat("material ", i, " '", pm.name(),
                                                     "': color has ", pm.color_size(),
                                                     " components, need 3 (RGB)"));
    }
    for (int k = 0; k < 3; ++k) m.color[k] = pm.color(k);
    if (pm.has_opacity()) m.opacity = pm.opacity();
    if (pm.has_ambient()) m.ambient = pm.ambient();
    if (pm.has_diffuse()) m.diffuse = pm.diffuse();
    if (pm.has_specular()) m.specular = pm.specular();
    if (pm.has_shininess()) m.shininess = pm.shininess();
    c.materials.push_back(std::move(m));
  }
  if (auto s = c.Validate(); !s.ok()) return s;
  return c;
}

absl::StatusOr<TransferFunction> ToTransferFunction(const v1::TransferFunction& ptf) {
  TransferFunction tf;
  for (int i = 0; i < ptf.points_size(); ++i) {
    const v1::TransferPoint& pp = ptf.points(i);
    if (pp.rgba_size() != 4) {
      return absl::InvalidArgumentError(absl::StrCat("transfer function point ", i, ": rgba has ",
                                                     pp.rgba_size(), " components, need 4"));
    }
    TransferPoint p;
    p.value = pp.value();
    for (int k = 0; k < 4; ++k) p.rgba[k] = pp.rgba(k);
    tf.points.push_back(p);
  }
  if (ptf.has_reference_step()) tf.reference_step = ptf.reference_step();
  if (ptf.has_shading()) tf.shading = ptf.shading();
  if (ptf.has_ambient()) tf.ambient = ptf.ambient();
  if (ptf.has_diffuse()) tf.diffuse = ptf.diffuse();
  if (ptf.has_specular()) tf.specular = ptf.specular();
  if (ptf.has_shininess()) tf.shininess = ptf.shininess();
  if (auto s = tf.Validate(); !s.ok()) return s;
  return tf;
}

namespace {

template <typename Proto, typename Fn>
auto LoadJsonFile(const std::string& path, Fn convert) -> decltype(convert(Proto{})) {
  auto text = ReadTextFile(path);
  if (!text.ok()) return text.status();
  Proto proto;
  if (auto s = ParseJson(*text, path, &proto); !s.ok()) return s;
  auto result = convert(proto);
  if (!result.ok()) {
    return absl::Status(result.status().code(),
                        absl::StrCat(path, ": ", result.status().message()));
  }
  return result;
}

}  // namespace

absl::StatusOr<Classification> LoadMaterials(const std::string& path) {
  return LoadJsonFile<v1::MaterialSet>(
      path, [](const v1::MaterialSet& m) { return ToClassification(m); });
}

absl::StatusOr<TransferFunction> LoadTransferFunction(const std::string& path) {
  return LoadJsonFile<v1::TransferFunction>(
      path, [](const v1::TransferFunction& t) { return ToTransferFunction(t); });
}

absl::StatusOr<CameraSpec> ToCameraSpec(const v1::View& v) {
  CameraSpec c;
  if (v.projection().empty() || v.projection() == "perspective") {
    c.projection = Projection::kPerspective;
  } else if (v.projection() == "orthographic") {
    c.projection = Projection::kOrthographic;
  } else {
    return absl::InvalidArgumentError(
        absl::StrCat("projection '", v.projection(), "' is not perspective or orthographic"));
  }
  c.azimuth_deg = v.azimuth();
  c.elevation_deg = v.elevation();
  if (v.has_zoom()) c.zoom = v.zoom();
  if (v.has_fov()) c.fov_deg = v.fov();
  c.width = v.width();
  c.height = v.height();
  if (v.has_explicit_view()) {
    const v1::ExplicitView& e = v.explicit_view();
    if (e.eye_size() != 3 || e.target_size() != 3 || (e.up_size() != 0 && e.up_size() != 3)) {
      return absl::InvalidArgumentError(
          "explicit_view: eye and target need 3 numbers, up 3 or none");
    }
    ExplicitView ev;
    ev.eye = {e.eye(0), e.eye(1), e.eye(2)};
    ev.target = {e.target(0), e.target(1), e.target(2)};
    if (e.up_size() == 3) ev.up = {e.up(0), e.up(1), e.up(2)};
    c.view = ev;
  }
  if (v.background_size() != 0 && v.background_size() != 3) {
    return absl::InvalidArgumentError(
        absl::StrCat("background has ", v.background_size(), " components, need 3"));
  }
  for (float b : v.background()) {
    if (!(b >= 0 && b <= 1))
      return absl::InvalidArgumentError("background components must be in [0, 1]");
  }
  if (!(v.step() >= 0) || !std::isfinite(v.step())) {
    return absl::InvalidArgumentError("step must be a non-negative number");
  }
  // Camera::Create checks sizes, zoom, fov and the explicit view.
  if (auto cam = Camera::Create(c, Vec3{1, 1, 1}); !cam.ok()) return cam.status();
  return c;
}

RenderSettings ToRenderSettings(const v1::View& v) {
  RenderSettings s;
  s.shadows = !v.has_shadows() || v.shadows();
  for (int c = 0; c < v.background_size() && c < 3; ++c) s.background[c] = v.background(c);
  s.step = v.step();
  return s;
}

std::string ToJson(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = true;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(message, &out, options);
  return out;
}

}  // namespace transtick
