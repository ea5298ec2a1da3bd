#include "convert.h"

#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>

#include <cctype>
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

namespace {

// Rewrites, in the JSON `tree` of a `type` message, every enum field whose
// value is a string to the enum's spelling: upper case, '_' for '-'
// ("test-rays" -> "TEST_RAYS"), and a whole number given to a string field
// to its digits (`"rings": 3` -> "3").
void SpellEnums(google::protobuf::Value& tree, const google::protobuf::Descriptor& type) {
  if (!tree.has_struct_value()) return;
  for (auto& [key, value] : *tree.mutable_struct_value()->mutable_fields()) {
    const google::protobuf::FieldDescriptor* f = type.FindFieldByName(key);
    for (int i = 0; f == nullptr && i < type.field_count(); ++i) {
      if (type.field(i)->json_name() == key) f = type.field(i);
    }
    if (f == nullptr || f->is_map()) continue;
    auto fix = [&](google::protobuf::Value& v) {
      if (f->type() == google::protobuf::FieldDescriptor::TYPE_ENUM && v.has_string_value()) {
        std::string name = v.string_value();
        for (char& c : name) c = c == '-' ? '_' : static_cast<char>(std::toupper(c));
        v.set_string_value(name);
      } else if (f->type() == google::protobuf::FieldDescriptor::TYPE_STRING &&
                 v.has_number_value() && std::abs(v.number_value()) < 1e15 &&
                 v.number_value() == std::floor(v.number_value())) {
        v.set_string_value(absl::StrCat(static_cast<int64_t>(v.number_value())));
      } else if (f->type() == google::protobuf::FieldDescriptor::TYPE_MESSAGE) {
        SpellEnums(v, *f->message_type());
      }
    };
    if (f->is_repeated() && value.has_list_value()) {
      for (auto& v : *value.mutable_list_value()->mutable_values()) fix(v);
    } else {
      fix(value);
    }
  }
}

}  // namespace

absl::Status ParseJson(std::string_view json, const std::string& source,
                       google::protobuf::Message* message) {
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = false;
  const google::protobuf::StringPiece text(json.data(), json.size());
  auto status = google::protobuf::util::JsonStringToMessage(text, message, options);
  if (!status.ok()) {
    // Enum values as job files wrote them when they were strings.
    google::protobuf::Value tree;
    std::string respelled;
    if (google::protobuf::util::JsonStringToMessage(text, &tree).ok()) {
      SpellEnums(tree, *message->GetDescriptor());
      if (google::protobuf::util::MessageToJsonString(tree, &respelled).ok()) {
        message->Clear();
        if (google::protobuf::util::JsonStringToMessage(respelled, message, options).ok()) {
          return absl::OkStatus();
        }
      }
    }
    message->Clear();
    return absl::InvalidArgumentError(absl::StrCat(source, ": not a valid ",
                                                   message->GetDescriptor()->name(), ": ",
                                                   std::string(status.message())));
  }
  return absl::OkStatus();
}

absl::StatusOr<int> ParseEnumValue(const google::protobuf::EnumDescriptor& type,
                                   std::string_view name, std::string_view what) {
  if (name.empty()) return 0;
  std::string spelled(name);
  for (char& c : spelled) c = c == '-' ? '_' : static_cast<char>(std::toupper(c));
  const google::protobuf::EnumValueDescriptor* v = type.FindValueByName(spelled);
  if (v != nullptr && v->number() != 0) return v->number();
  std::string names;
  for (int i = 0; i < type.value_count(); ++i) {
    if (type.value(i)->number() == 0) continue;
    absl::StrAppend(&names, names.empty() ? "" : ", ",
                    EnumValueName(type, type.value(i)->number()));
  }
  return absl::InvalidArgumentError(
      absl::StrCat(std::string(what), " '", std::string(name), "' is not one of ", names));
}

std::string EnumValueName(const google::protobuf::EnumDescriptor& type, int value) {
  const google::protobuf::EnumValueDescriptor* v = type.FindValueByNumber(value);
  if (v == nullptr) return absl::StrCat(value);
  std::string name = v->name();
  for (char& c : name) c = c == '_' ? '-' : static_cast<char>(std::tolower(c));
  return name;
}

absl::StatusOr<v1::BalanceMode> EffectiveBalance(const v1::Job& job, const v1::View& view) {
  for (v1::BalanceMode m : {view.balance(), job.balance()}) {
    if (!v1::BalanceMode_IsValid(m)) {
      return absl::InvalidArgumentError(absl::StrCat("balance ", static_cast<int>(m),
                                                     " is not a balancing mode"));
    }
  }
  if (view.balance() != v1::BALANCE_DEFAULT) return view.balance();
  return job.balance() == v1::BALANCE_DEFAULT ? v1::OFF : job.balance();
}

absl::StatusOr<BalanceRule> ToBalanceRule(v1::BalanceRule rule) {
  switch (rule) {
    case v1::BALANCE_RULE_DEFAULT:
    case v1::COST:
      return BalanceRule::kCost;
    case v1::PAPER:
      return BalanceRule::kPaper;
    default:
      return absl::InvalidArgumentError(
          absl::StrCat("balance_rule ", static_cast<int>(rule), " is not a rule"));
  }
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
  switch (set.surface()) {
    case v1::SURFACE_DEFAULT:
    case v1::SMOOTH:
      c.surface = SurfaceModel::kSmooth;
      break;
    case v1::VOXEL:
      c.surface = SurfaceModel::kVoxel;
      break;
    default:
      return absl::InvalidArgumentError(
          absl::StrCat("surface ", static_cast<int>(set.surface()), " is not a surface model"));
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

absl::StatusOr<v1::Dataset> ResolvePreset(const v1::Dataset& dataset,
                                          const std::array<float, 2>& range) {
  if (!dataset.has_preset()) return dataset;
  const v1::Preset& preset = dataset.preset();
  v1::RenderMode mode = preset.mode();
  if (mode == v1::RENDER_MODE_UNSPECIFIED) {
    mode = v1::DVR;
    for (const PresetInfo& info : ListPresets()) {
      if (info.name == preset.name() && info.surfaces) mode = v1::SURFACES;
    }
  }
  v1::Dataset out = dataset;
  out.clear_preset();
  if (mode == v1::SURFACES) {
    auto c = PresetMaterials(preset.name(), range);
    if (!c.ok()) return c.status();
    v1::MaterialSet& set = *out.mutable_materials();
    set.set_surface(preset.surface());
    for (const Material& m : c->materials) {
      v1::Material& pm = *set.add_materials();
      pm.set_name(m.name);
      pm.set_min(m.min);
      pm.set_max(m.max);
      for (float x : m.color) pm.add_color(x);
      pm.set_opacity(m.opacity);
      pm.set_ambient(m.ambient);
      pm.set_diffuse(m.diffuse);
      pm.set_specular(m.specular);
      pm.set_shininess(m.shininess);
    }
  } else if (mode == v1::DVR) {
    if (preset.surface() != v1::SURFACE_DEFAULT) {
      return absl::InvalidArgumentError(absl::StrCat(
          "preset '", preset.name(), "': a surface model is for surfaces mode, not dvr"));
    }
    auto tf = PresetTransfer(preset.name(), range);
    if (!tf.ok()) return tf.status();
    v1::TransferFunction& t = *out.mutable_transfer();
    for (const TransferPoint& point : tf->points) {
      v1::TransferPoint& pp = *t.add_points();
      pp.set_value(point.value);
      for (float x : point.rgba) pp.add_rgba(x);
    }
    t.set_reference_step(tf->reference_step);
    t.set_shading(tf->shading);
    t.set_ambient(tf->ambient);
    t.set_diffuse(tf->diffuse);
    t.set_specular(tf->specular);
    t.set_shininess(tf->shininess);
  } else {
    return absl::InvalidArgumentError(
        absl::StrCat("preset '", preset.name(), "': mode ", static_cast<int>(mode),
                     " is not surfaces or dvr"));
  }
  return out;
}

absl::StatusOr<CameraSpec> ToCameraSpec(const v1::View& v) {
  CameraSpec c;
  switch (v.projection()) {
    case v1::PROJECTION_DEFAULT:
    case v1::PERSPECTIVE:
      c.projection = Projection::kPerspective;
      break;
    case v1::ORTHOGRAPHIC:
      c.projection = Projection::kOrthographic;
      break;
    default:
      return absl::InvalidArgumentError(absl::StrCat(
          "projection ", static_cast<int>(v.projection()), " is not perspective or orthographic"));
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
  if (v.has_samples() && (v.samples() < 1 || v.samples() > kMaxSamplesPerPixel)) {
    return absl::InvalidArgumentError(absl::StrCat("samples ", v.samples(), " must be in [1, ",
                                                   kMaxSamplesPerPixel, "]"));
  }
  // Camera::Create checks sizes, zoom, fov and the explicit view.
  if (auto cam = Camera::Create(c, Vec3{1, 1, 1}); !cam.ok()) return cam.status();
  return c;
}

absl::StatusOr<FrameRequest> ToFrameRequest(const v1::View& view) {
  auto camera = ToCameraSpec(view);
  if (!camera.ok()) return camera.status();
  return FrameRequest{*camera, ToRenderSettings(view)};
}

absl::StatusOr<v1::View> ToVolumeFrame(const v1::View& view, const Direction& direction,
                                       const Vec3& volume_extent) {
  if (direction == kIdentityDirection) return view;
  auto world = ToCameraSpec(view);
  if (!world.ok()) return world.status();
  auto local = ToVolumeFrame(*world, direction, volume_extent);
  if (!local.ok()) return local.status();
  v1::View out = view;
  out.clear_azimuth();
  out.clear_elevation();
  v1::ExplicitView& e = *out.mutable_explicit_view();
  e.Clear();
  for (int a = 0; a < 3; ++a) {
    e.add_eye(local->view->eye[a]);
    e.add_target(local->view->target[a]);
    e.add_up(local->view->up[a]);
  }
  return out;
}

absl::StatusOr<RenderMode> ToRenderMode(v1::RenderMode mode) {
  switch (mode) {
    case v1::SURFACES:
      return RenderMode::kSurfaces;
    case v1::DVR:
      return RenderMode::kDvr;
    default:
      return absl::InvalidArgumentError(
          absl::StrCat("render mode ", EnumValueName(*v1::RenderMode_descriptor(), mode),
                       " is neither SURFACES nor DVR"));
  }
}

v1::RenderMode ToProto(RenderMode mode) {
  return mode == RenderMode::kDvr ? v1::DVR : v1::SURFACES;
}

RenderSettings ToRenderSettings(const v1::View& v) {
  RenderSettings s;
  s.shadows = !v.has_shadows() || v.shadows();
  for (int c = 0; c < v.background_size() && c < 3; ++c) s.background[c] = v.background(c);
  s.step = v.step();
  s.samples = v.has_samples() ? v.samples() : 1;
  return s;
}

absl::StatusOr<v1::ImageEncoding> ToImageEncoding(v1::ImageEncoding encoding,
                                                  std::string_view what) {
  switch (encoding) {
    case v1::IMAGE_ENCODING_DEFAULT:
    case v1::FLOAT32:
      return v1::FLOAT32;
    case v1::RGB8:
      return v1::RGB8;
    default:
      return absl::InvalidArgumentError(absl::StrCat(std::string(what), " ",
                                                     static_cast<int>(encoding),
                                                     " is not an encoding (float32 or rgb8)"));
  }
}

int PixelBytes(v1::ImageEncoding encoding) { return encoding == v1::RGB8 ? 3 : 12; }

const std::string& ChunkBytes(const v1::ImageChunk& chunk, v1::ImageEncoding encoding) {
  return encoding == v1::RGB8 ? chunk.rgb8() : chunk.rgb();
}

std::string* MutableChunkBytes(v1::ImageChunk* chunk, v1::ImageEncoding encoding) {
  return encoding == v1::RGB8 ? chunk->mutable_rgb8() : chunk->mutable_rgb();
}

bool ChunkBytesFit(const v1::ImageChunk& chunk, v1::ImageEncoding encoding) {
  const int64_t rows = int64_t{chunk.row_end()} - chunk.row_begin();
  if (rows < 0 || chunk.width() < 0) return false;
  const std::string& other = encoding == v1::RGB8 ? chunk.rgb() : chunk.rgb8();
  return other.empty() && ChunkBytes(chunk, encoding).size() ==
                              static_cast<uint64_t>(rows) * chunk.width() * PixelBytes(encoding);
}

absl::StatusOr<v1::ImageEncoding> ChunkEncoding(const v1::ImageChunk& chunk) {
  for (v1::ImageEncoding e : {v1::FLOAT32, v1::RGB8}) {
    if (ChunkBytesFit(chunk, e)) return e;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("image chunk of rows [", chunk.row_begin(), ", ", chunk.row_end(), ") of width ",
                   chunk.width(), " with ", chunk.rgb().size(), " bytes of float32 and ",
                   chunk.rgb8().size(), " of rgb8: not the rows' size in exactly one of them"));
}

std::string ToJson(const google::protobuf::Message& message, bool indent) {
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = indent;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(message, &out, options);
  return out;
}

}  // namespace transtick
