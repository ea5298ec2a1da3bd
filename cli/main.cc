// transtick: the command-line client.
//
//   transtick render --volume FILE [--materials FILE | --transfer FILE] ...
//   transtick info --volume FILE
//
// `transtick help` lists the commands; `transtick CMD --help` gives their flags.

#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <thread>

#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "client.h"
#include "clock.h"
#include "cluster.grpc.pb.h"
#include "cluster_model.h"
#include "convert.h"
#include "daemon.h"
#include "flags.h"
#include "gateway.h"
#include "heap.h"
#include "local_cluster.h"
#include "progress.h"
#include "rpc_channel.h"
#include "rpc_status.h"
#include "transtick/camera.h"
#include "transtick/image_io.h"
#include "transtick/orientation.h"
#include "transtick/presets.h"
#include "transtick/render.h"
#include "transtick/scene.h"
#include "transtick/volume_io.h"
#include "version.h"
#include "volumes.h"

namespace transtick {
namespace {

constexpr char kUsage[] = R"(transtick: a volume ray tracer (sticks, ray dataflow)

usage: transtick COMMAND [flags]     (transtick COMMAND --help for its flags)

commands:
  render    render one image (on an embedded cluster by default, or --root)
  info      describe a volume: size, spacing, values, histogram
  submit    submit a job file to a running cluster and save its images
  watch     follow a running job to its end and save its images
  status    jobs and workers of a running cluster
  cancel    cancel a job
  health    exit 0 when every daemon named reports SERVING
  view      the web viewer: look around volumes live in a browser
  presets   list the named classifications (--preset)
  volumes   list what a cluster's root (or a data directory) offers to open
  version   print the version

docs: README.md, docs/formats.md (materials, transfer functions, job files, stats)
)";

std::vector<FlagDoc> With(std::vector<FlagDoc> a, const std::vector<FlagDoc>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

const std::vector<FlagDoc> kVolumeFlags = {
    {"volume", "FILE",
     "NRRD (.nrrd, .nhdr), NIfTI-1 (.nii, .nii.gz), MetaImage (.mha, .mhd),\n"
     "VTK image data (.vti), a directory of DICOM files (DIR#UID: one series of\n"
     "several in it), Levoy's .den; any other extension, or --raw-dims given, is\n"
     "headerless raw"},
    {"raw-dims", "XxYxZ", "a raw volume's size"},
    {"raw-type", "T", "uint8|int8|uint16|int16|uint32|int32|float|double (default uint8)"},
    {"raw-endian", "little|big", "byte order of a raw volume (default little)"},
    {"raw-spacing", "X,Y,Z", "voxel size of a raw volume (default 1,1,1)"},
    {"raw-skip", "BYTES", "header bytes to skip in a raw volume (default 0)"},
    {"max-volume-mb", "N", "refuse volumes larger than N MiB in memory (default 8192)"},
};

const CommandDoc kInfoDoc = {
    "transtick info", "", "Describes a volume: its size, sample type, spacing, range of values, its\n"
    "orientation (docs/formats.md#orientation) and a histogram of 16 bins, which helps\n"
    "choose material intervals.", 0, 0, kVolumeFlags, ""};

const std::vector<FlagDoc> kQuietFlag = {
    {"quiet", "", "no progress (on a terminal, a line with the time left; elsewhere a line\n"
                  "every 5 s); warnings and errors are still printed"}};

const CommandDoc kRenderDoc = {
    "transtick render", "",
    "Renders one image of a volume: on an embedded cluster of workers on loopback by\n"
    "default, in this process with --local 0 (the reference every cluster image equals\n"
    "bit for bit), or on a running cluster with --root.",
    0, 0,
    With(With(kVolumeFlags,
              {
                  {"materials", "FILE", "surfaces mode classification (JSON, docs/formats.md)"},
                  {"transfer", "FILE", "dvr mode transfer function (JSON)"},
                  {"preset", "NAME",
                   "a named classification instead: ct-bone, ct-skin-bone, ct-angio,\n"
                   "mr-brain; the colormaps grey, hot, cool-warm for dvr (docs/formats.md#presets)"},
                  {"mode", "surfaces|dvr",
                   "default: surfaces with --materials, dvr with --transfer, surfaces\n"
                   "with a --preset that has materials"},
                  {"surface", "smooth|voxel",
                   "surfaces on the trilinear field, hit exactly (default), or the\n"
                   "paper's voxel faces (overrides the materials' or the preset's)"},
                  {"azimuth", "DEG", "orbit: rotation about the world's Y axis (0 looks along -Z)"},
                  {"elevation", "DEG", "orbit: tilt toward +Y"},
                  {"zoom", "F", "magnification: in an orbit 1 frames the whole volume; with --eye\n"
                               "it narrows the field of view by F (default 1)"},
                  {"eye", "X,Y,Z", "explicit view, with --target: world units (patient LPS), volume\n"
                                   "centred at 0"},
                  {"target", "X,Y,Z", "the point looked at"},
                  {"up", "X,Y,Z", "the explicit view's up (default 0,1,0)"},
                  {"projection", "perspective|orthographic", "camera model (default perspective)"},
                  {"fov", "DEG", "perspective field of view (default 30)"},
                  {"size", "WxH", "image size, at most 8192x8192 (default 400x400)"},
                  {"shadows", "on|off", "shadow rays in surfaces mode (default on)"},
                  {"samples", "N",
                   "primary rays per pixel, 1-64, at a fixed stratified pattern\n"
                   "(anti-aliasing; default 1)"},
                  {"background", "R,G,B", "background colour in [0, 1] (default 0,0,0)"},
                  {"step", "S", "dvr sample step in world units (default half the smallest spacing)"},
                  {"local", "N",
                   "workers of the embedded cluster (default: one per core); 0 renders\n"
                   "in this process without gRPC"},
                  {"rings", "R", "rings of the embedded cluster, or auto (default 1)"},
                  {"balance", "off|test-rays|previous-frame",
                   "static load balancing of the slabs on a cluster (default off)"},
                  {"balance-grid", "N", "test rays per side of the image for test-rays (default 64)"},
                  {"balance-rule", "cost|paper", "how cuts follow from costs (default cost)"},
                  {"root", "HOST:PORT",
                   "render on a running cluster; --volume is then relative to the\n"
                   "root's data directory"},
                  {"threads", "N",
                   "tracing threads of --local 0, and of each embedded worker\n"
                   "(default: one per core)"},
                  {"out", "FILE", "a .png/.jpg (8-bit) or .tif/.exr/.hdr (float) image (default\n"
                                  "transtick.png); its directory must exist"},
                  {"stats", "FILE.json", "frame statistics as JSON (docs/formats.md)"},
              }),
         With(kQuietFlag, ClientSecurityFlagDocs())),
    "example:\n  transtick render --volume head.nrrd --materials examples/cthead_materials.json \\\n"
    "      --azimuth 45 --size 400x400 --out head.png"};

// submit and watch: both follow a job to its end and save its images.
const std::vector<FlagDoc> kFollowFlags = With(
    With({{"root", "HOST:PORT", "the cluster's root (required)"},
          {"out-dir", "DIR", "where images with relative paths go (default .); made if\n"
                             "missing, but not its parents"},
          {"stats", "FILE.json", "every frame's statistics, as a JSON array"}},
         kQuietFlag),
    ClientSecurityFlagDocs());

const CommandDoc kSubmitDoc = {
    "transtick submit", "JOB.json",
    "Submits a job file (docs/formats.md, \"Job file\") to a running cluster, follows it\n"
    "to its end and saves each frame's image: a relative output path beneath --out-dir.\n"
    "If the connection breaks, it watches again and gets the frames it lacks.",
    1, 1,
    kFollowFlags,
    "example:\n  transtick submit examples/cthead_job.json --root 127.0.0.1:7000"};

const CommandDoc kWatchDoc = {
    "transtick watch", "JOB_ID",
    "Follows a job already submitted (by this client, or by another with an admin token)\n"
    "to its end, showing its progress and saving every frame's image, also those\n"
    "rendered before the watch began: the way back to a job after its submit's terminal\n"
    "was lost.",
    1, 1,
    kFollowFlags,
    ""};

const CommandDoc kStatusDoc = {"transtick status", "",
                               "Lists the workers of a running cluster, with their memory, rings and "
                               "slabs, and its jobs.",
                               0, 0,
                               With({{"root", "HOST:PORT", "the cluster's root (required)"}},
                                    ClientSecurityFlagDocs()),
                               ""};

const CommandDoc kVolumesDoc = {
    "transtick volumes",
    "",
    "Lists the volumes a running cluster's root offers (--root), or that a root\n"
    "serving --data-dir DIR would offer: each as the path a job's \"volume\" takes,\n"
    "its size, and for a DICOM series what its headers say (one line per series of\n"
    "a study, as DIR#UID) and why it would not open (docs/formats.md#volumes-listing).",
    0,
    0,
    With({{"root", "HOST:PORT", "the cluster's root"},
          {"data-dir", "DIR", "list DIR here, as a root serving it would"}},
         ClientSecurityFlagDocs()),
    ""};

const CommandDoc kCancelDoc = {"transtick cancel", "JOB_ID", "Cancels a queued or running job.",
                               1, 1,
                               With({{"root", "HOST:PORT", "the cluster's root (required)"}},
                                    ClientSecurityFlagDocs()),
                               ""};

const CommandDoc kHealthDoc = {
    "transtick health", "",
    "Asks each daemon's standard gRPC health service; exits 0 when every one reports\n"
    "SERVING, 1 otherwise, with one line per daemon (container probes use it).",
    0, 0,
    With({{"addr", "HOST:PORT[,...]", "the daemons to ask (default 127.0.0.1:7000)"},
          {"role", "root|worker|display", "what they are: their certificate's role (default root)"},
          {"timeout", "S", "seconds to wait for each (default 3)"}},
         ClientSecurityFlagDocs()),
    ""};

const CommandDoc kVersionDoc = {"transtick version", "", "Prints the version.", 0, 0, {}, ""};

const CommandDoc kViewDoc = {
    "transtick view", "",
    "Serves the web viewer (docs/viewer.md) for an embedded cluster of workers on\n"
    "loopback, or for a running cluster with --root, and prints its address. Open it in\n"
    "a browser: drag to orbit, wheel to zoom, edit the classification beside the\n"
    "volume's histogram, follow jobs and each worker's load. Runs until interrupted.",
    0, 0,
    {{"data-dir", "DIR",
      "the embedded root's data directory: the volumes the page lists (default:\n"
      "--volume's directory, else $TRANSTICK_DATA_DIR, else .)"},
     {"volume", "FILE", "the volume the page opens first (in the data directory)"},
     {"preset", "NAME", "its classification (transtick presets lists them)"},
     {"local", "N", "workers of the embedded cluster (default: one per core)"},
     {"rings", "R", "rings of the embedded cluster, or auto (default 1)"},
     {"threads", "N", "tracing threads of each embedded worker (default: one per core)"},
     {"root", "HOST:PORT", "serve the viewer for this running cluster instead"},
     {"listen", "HOST:PORT", "where the page is served (default 127.0.0.1:8080; port 0 picks one)"},
     {"https-cert", "FILE", "serve HTTPS with this certificate (PEM), with --https-key"},
     {"https-key", "FILE", "its key"},
     {"static-dir", "DIR", "serve the page's files from DIR (working on the page)"},
     {"tls-ca", "FILE", "the cluster's CA certificate: TLS to --root; browsers then send tokens"},
     {"insecure", "", "allow plaintext HTTP on an address that is not loopback"}},
    "example:\n  transtick view --volume ../shared/data/cthead.nrrd --preset ct-bone"};

const CommandDoc kPresetsDoc = {"transtick presets", "",
                                "Lists the named classifications of --preset and job files' "
                                "\"preset\"\n(docs/formats.md#presets).",
                                0, 0, {}, ""};

// Parses a command's flags; prints its usage for --help (returning 0 in
// *exit) and the error otherwise (returning 2).
std::optional<Flags> ParseCommand(int argc, char** argv, const CommandDoc& doc, int* exit) {
  auto flags = Flags::Parse(argc, argv, 2, doc);
  if (!flags.ok()) {
    std::cerr << doc.name << ": " << flags.status().message() << "\n";
    *exit = 2;
    return std::nullopt;
  }
  if (flags->Has("help")) {
    std::cout << Usage(doc);
    *exit = 0;
    return std::nullopt;
  }
  return *std::move(flags);
}

// Refuses flags that contradict each other: `a` given with any of `b`.
absl::Status Exclusive(const Flags& flags, const std::string& a, std::initializer_list<const char*> b,
                       const std::string& why) {
  if (!flags.Has(a)) return absl::OkStatus();
  for (const char* other : b) {
    if (flags.Has(other)) {
      return absl::InvalidArgumentError(absl::StrCat("--", a, " and --", other,
                                                     " contradict each other: ", why));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<Volume> LoadVolume(const Flags& flags) {
  if (!flags.Has("volume")) return absl::InvalidArgumentError("--volume FILE is required");
  ReadOptions options;
  auto mb = flags.GetInt("max-volume-mb", 8192);
  if (!mb.ok()) return mb.status();
  if (*mb < 1) return absl::InvalidArgumentError("--max-volume-mb must be at least 1");
  options.max_bytes = static_cast<uint64_t>(*mb) << 20;
  const std::string path = flags.Get("volume");
  if (!flags.Has("raw-dims")) return ReadVolume(path, options);
  RawSpec spec;
  auto dims = flags.GetDims("raw-dims", 3);
  if (!dims.ok()) return dims.status();
  for (int a = 0; a < 3; ++a) spec.dims[a] = (*dims)[a];
  auto type = ParseScalarType(flags.Get("raw-type", "uint8"));
  if (!type.ok()) return type.status();
  spec.type = *type;
  std::string endian = flags.Get("raw-endian", "little");
  if (endian != "little" && endian != "big") {
    return absl::InvalidArgumentError("--raw-endian must be little or big");
  }
  spec.byte_order = endian == "big" ? ByteOrder::kBig : ByteOrder::kLittle;
  if (flags.Has("raw-spacing")) {
    auto sp = flags.GetTriple("raw-spacing");
    if (!sp.ok()) return sp.status();
    spec.spacing = *sp;
  }
  auto skip = flags.GetInt("raw-skip", 0);
  if (!skip.ok()) return skip.status();
  if (*skip < 0) return absl::InvalidArgumentError("--raw-skip must not be negative");
  spec.header_bytes = static_cast<uint64_t>(*skip);
  return ReadRaw(path, spec, options);
}

// The raw volume's flags describe a raw volume: without --raw-dims they
// would be ignored.
absl::Status CheckRawFlags(const Flags& flags) {
  if (flags.Has("raw-dims")) return absl::OkStatus();
  for (const char* f : {"raw-type", "raw-endian", "raw-spacing", "raw-skip"}) {
    if (flags.Has(f)) {
      return absl::InvalidArgumentError(
          absl::StrCat("--", f, " describes a raw volume and needs --raw-dims"));
    }
  }
  return absl::OkStatus();
}

// Prints the error; the exit status is 2 for what the user gave wrong (a
// malformed file, a bad flag), 1 for the rest.
int Fail(const char* command, const absl::Status& s) {
  std::cerr << "transtick " << command << ": " << s.message() << "\n";
  return s.code() == absl::StatusCode::kInvalidArgument ? 2 : 1;
}

int Info(int argc, char** argv) {
  int exit = 0;
  auto flags = ParseCommand(argc, argv, kInfoDoc, &exit);
  if (!flags) return exit;
  if (absl::Status s = CheckRawFlags(*flags); !s.ok()) return Fail("info", s);
  auto volume = LoadVolume(*flags);
  // A malformed file exits 2, as for render (README).
  if (!volume.ok()) return Fail("info", volume.status());
  auto range = volume->Range();
  std::cout << flags->Get("volume") << ": " << volume->dims[0] << "x" << volume->dims[1] << "x"
            << volume->dims[2] << " " << ScalarTypeName(volume->source_type) << ", spacing "
            << volume->spacing[0] << " " << volume->spacing[1] << " " << volume->spacing[2]
            << ", values " << range[0] << " .. " << range[1] << "\n"
            << "  " << DescribeOrientation(*volume) << "\n";
  for (const std::string& note : volume->notes) std::cout << "  note: " << note << "\n";
  // A coarse histogram helps choose material intervals.
  constexpr int kBins = 16;
  // Its NaN and infinite values (outside Range()) are counted apart.
  const std::vector<uint64_t> hist = Histogram(volume->values, range, kBins);
  uint64_t not_finite = volume->values.size();
  for (uint64_t n : hist) not_finite -= n;
  const double lo = range[0], hi = range[1];
  const double width = hi > lo ? (hi - lo) / kBins : 1;
  for (int b = 0; b < kBins; ++b) {
    std::printf("  [%10.1f, %10.1f)  %6.2f%%\n", lo + b * width, lo + (b + 1) * width,
                100.0 * hist[b] / volume->values.size());
  }
  if (not_finite > 0) {
    std::printf("  NaN or infinite        %6.2f%%\n", 100.0 * not_finite / volume->values.size());
  }
  return 0;
}

// The view a render's flags describe, as the job API has it, so the
// in-process and cluster renders take their camera from one place.
absl::StatusOr<v1::View> ViewFromFlags(const Flags& flags) {
  v1::View v;
  v.set_width(400);
  v.set_height(400);
  if (flags.Has("size")) {
    auto size = flags.GetDims("size", 2);
    if (!size.ok()) return size.status();
    v.set_width((*size)[0]);
    v.set_height((*size)[1]);
  }
  auto az = flags.GetDouble("azimuth", 0);
  auto el = flags.GetDouble("elevation", 0);
  auto zoom = flags.GetDouble("zoom", 1);
  auto fov = flags.GetDouble("fov", 30);
  auto step = flags.GetDouble("step", 0);
  for (const auto* d : {&az, &el, &zoom, &fov, &step}) {
    if (!d->ok()) return d->status();
  }
  v.set_azimuth(*az);
  v.set_elevation(*el);
  v.set_zoom(*zoom);
  v.set_fov(*fov);
  if (*step < 0) return absl::InvalidArgumentError("--step must be positive");
  v.set_step(*step);
  auto projection = ParseEnum<v1::Projection>(flags.Get("projection", "perspective"), "--projection");
  if (!projection.ok()) return projection.status();
  v.set_projection(*projection);
  if (flags.Has("eye") || flags.Has("target")) {
    if (!flags.Has("eye") || !flags.Has("target")) {
      return absl::InvalidArgumentError("--eye and --target go together");
    }
    for (const char* name : {"eye", "target", "up"}) {
      if (!flags.Has(name)) continue;
      auto t = flags.GetTriple(name);
      if (!t.ok()) return t.status();
      auto* field = std::string(name) == "eye"      ? v.mutable_explicit_view()->mutable_eye()
                    : std::string(name) == "target" ? v.mutable_explicit_view()->mutable_target()
                                                    : v.mutable_explicit_view()->mutable_up();
      for (double x : *t) field->Add(x);
    }
  }
  auto shadows = flags.GetOnOff("shadows", true);
  if (!shadows.ok()) return shadows.status();
  v.set_shadows(*shadows);
  if (flags.Has("samples")) {
    auto samples = flags.GetInt("samples", 1);
    if (!samples.ok()) return samples.status();
    v.set_samples(*samples);
  }
  if (flags.Has("background")) {
    auto bg = flags.GetTriple("background");
    if (!bg.ok()) return bg.status();
    for (double c : *bg) v.add_background(static_cast<float>(c));
  }
  v.set_output(flags.Get("out", "transtick.png"));
  if (!IsSupportedImagePath(v.output())) {
    return absl::InvalidArgumentError(absl::StrCat("--out: '", v.output(),
                                                   "' is not an image format transtick writes (",
                                                   SupportedImageList(), ")"));
  }
  // Checks ranges (image size, zoom, projection, background) up front.
  if (auto c = ToCameraSpec(v); !c.ok()) return c.status();
  return v;
}

// Takes the command's TLS and token flags (security.h) for its channels.
absl::Status UseSecurity(const Flags& flags) {
  auto security = SecurityFromFlags(flags, /*daemon=*/false);
  if (!security.ok()) return security.status();
  SetSecurity(*std::move(security));
  return absl::OkStatus();
}

std::string VersionText() {
  return absl::StrCat("transtick ", TRANSTICK_VERSION, " (", TRANSTICK_GIT_COMMIT, "), gRPC ",
                      grpc::Version(), ", API transtick.v1");
}

void WriteStats(const std::string& path, const google::protobuf::Message& m) {
  std::ofstream f(path);
  f << ToJson(m);
  if (!f) std::cerr << "transtick: cannot write " << path << "\n";
}

// --local 0: the reference renderer, in this process without gRPC.
int RenderInProcess(const Flags& flags, const v1::View& view, bool dvr,
                    Classification classification, TransferFunction transfer,
                    const v1::Dataset& dataset) {
  auto fail = [](const absl::Status& s) { return Fail("render", s); };
  auto threads = flags.GetInt("threads", 0);
  if (!threads.ok()) return fail(threads.status());
  if (*threads < 0 || *threads > 1024) {
    return fail(absl::InvalidArgumentError("--threads must be in [0, 1024]"));
  }
  auto t_load = std::chrono::steady_clock::now();
  auto volume = LoadVolume(flags);
  if (!volume.ok()) return fail(volume.status());
  const double load_ms = MsSince(t_load);
  if (dataset.has_preset()) {
    // As the root resolves it: against the volume's range.
    auto resolved = ResolvePreset(dataset, volume->Range());
    if (!resolved.ok()) return fail(resolved.status());
    if (dvr) {
      auto tf = ToTransferFunction(resolved->transfer());
      if (!tf.ok()) return fail(tf.status());
      transfer = *std::move(tf);
    } else {
      auto c = ToClassification(resolved->materials());
      if (!c.ok()) return fail(c.status());
      classification = *std::move(c);
    }
  }
  // As the root's, before the scene takes the volume's samples: what the
  // reader passed over or chose, then what of the classification shows
  // nothing.
  std::vector<std::string> warnings = volume->notes;
  for (std::string& w :
       dvr ? UnseenTransfer(transfer, *volume) : UnseenMaterials(classification, *volume)) {
    warnings.push_back(std::move(w));
  }
  auto t_prepare = std::chrono::steady_clock::now();
  auto scene = dvr ? Scene::ForDvr(std::move(*volume), transfer)
                   : Scene::ForSurfaces(std::move(*volume), classification);
  if (!scene.ok()) return fail(scene.status());
  const double prepare_ms = MsSince(t_prepare);
  Vec3 extent{volume->dims[0] * volume->spacing[0], volume->dims[1] * volume->spacing[1],
              volume->dims[2] * volume->spacing[2]};
  // The camera in the volume's frame, mapped as the root maps it for its
  // workers (ToVolumeFrame), so both renders see the same doubles.
  auto local_view = ToVolumeFrame(view, volume->direction, extent);
  if (!local_view.ok()) return fail(local_view.status());
  auto camera = Camera::Create(*ToCameraSpec(*local_view), extent);
  if (!camera.ok()) return fail(camera.status());
  Progress progress(Progress::ForStderr(flags.Has("quiet")));
  for (const std::string& w : warnings) progress.Warn("warning: " + w);
  RenderStats stats;
  auto image = RenderLocal(*scene, *camera, ToRenderSettings(view), *threads, &stats,
                           [&progress](uint64_t done, uint64_t total) {
                             progress.Update(static_cast<double>(done) / total, "rendering");
                           });
  progress.Finish();
  if (!image.ok()) return fail(image.status());
  const std::string out = view.output();
  if (auto s = WriteImage(out, *image); !s.ok()) return fail(s);

  v1::FrameStats fs;
  fs.set_frame_ms(stats.frame_ms);
  fs.set_prepare_ms(prepare_ms);
  fs.set_load_ms(load_ms);
  fs.set_threads(stats.threads);
  fs.set_mode(dvr ? v1::DVR : v1::SURFACES);
  fs.set_width(view.width());
  fs.set_height(view.height());
  const TraceCounters& c = stats.counters;
  fs.mutable_rays()->set_primary(c.primary);
  fs.mutable_rays()->set_shadow(c.shadow);
  fs.mutable_rays()->set_total(c.primary + c.shadow);
  fs.set_segments(c.segments);
  fs.set_surface_hits(c.surface_hits);
  fs.set_samples(c.samples);
  fs.set_rays_truncated(c.truncated);
  for (const std::string& w : warnings) fs.add_warnings(w);
  const Sticks& sticks = scene->sticks();
  uint64_t encoded = 0;
  for (int by = 0; by < sticks.BlocksY(); ++by)
    for (int bx = 0; bx < sticks.BlocksX(); ++bx) encoded += sticks.EncodeBlock(bx, by).size();
  const uint64_t raw = volume->VoxelCount() * ScalarTypeSize(volume->source_type);
  auto* ss = fs.mutable_sticks();
  ss->set_sticks(sticks.StickCount());
  ss->set_encoded_bytes(encoded);
  ss->set_memory_bytes(sticks.MemoryBytes());
  ss->set_raw_volume_bytes(raw);
  ss->set_ratio(raw ? static_cast<double>(encoded) / raw : 0);
  ss->set_scalar_bytes(scene->scalars().size() * sizeof(float));
  for (int a = 0; a < 3; ++a) fs.add_volume_dims(volume->dims[a]);
  fs.set_rays_per_second(stats.frame_ms > 0 ? (c.primary + c.shadow) / (stats.frame_ms / 1e3) : 0);
  if (!flags.Has("quiet")) std::fprintf(stderr,
               "%s: %dx%d %s in %.1f ms on %d threads (%llu primary + %llu shadow rays); "
               "sticks %.2f MB = %.1f%% of the raw volume\n",
               out.c_str(), view.width(), view.height(), dvr ? "dvr" : "surfaces", stats.frame_ms,
               stats.threads, static_cast<unsigned long long>(c.primary),
               static_cast<unsigned long long>(c.shadow), encoded / 1e6, 100.0 * ss->ratio());
  if (flags.Has("stats")) WriteStats(flags.Get("stats"), fs);
  return 0;
}

void PrintClusterFrame(const v1::ClusterFrameStats& fs) {
  std::fprintf(stderr, "frame %dx%d in %.1f ms on %d workers (%d ring%s), max/mean active %.2f\n",
               fs.width(), fs.height(), fs.frame_ms(), fs.workers_size(), fs.rings(),
               fs.rings() == 1 ? "" : "s", fs.active_imbalance());
  if (fs.balance() != v1::OFF) {
    // Each ring's cuts run from 0 to the number of planes: "[0 64 128] [0 70 128]".
    auto rings = [](const google::protobuf::RepeatedField<int32_t>& cuts) {
      std::string out;
      for (int i = 0; i < cuts.size(); ++i) {
        if (cuts[i] == 0) out += i ? "] [" : "[";
        out += std::to_string(cuts[i]);
        if (i + 1 < cuts.size() && cuts[i + 1] != 0) out += " ";
      }
      return cuts.empty() ? out : out + "]";
    };
    std::fprintf(stderr, "  balance %s: cuts %s -> %s, %.1f ms, %d planes moved\n",
                 EnumName(fs.balance()).c_str(), rings(fs.cuts_before()).c_str(),
                 rings(fs.cuts_after()).c_str(), fs.balance_ms(), fs.planes_moved());
  }
  for (const auto& w : fs.workers()) {
    std::fprintf(stderr,
                 "  ring %d slab [%3d, %3d): elapsed %7.1f ms, active %7.1f ms, traced %8llu, "
                 "sent %7llu, received %7llu\n",
                 w.ring(), w.slab_size() > 0 ? w.slab(0) : -1, w.slab_size() > 1 ? w.slab(1) : -1,
                 w.elapsed_ms(), w.active_ms(), static_cast<unsigned long long>(w.rays_traced()),
                 static_cast<unsigned long long>(w.rays_sent()),
                 static_cast<unsigned long long>(w.rays_received()));
  }
}

// Flags of `render` that contradict each other, or that the chosen mode or
// renderer would ignore: each is refused, naming both.
absl::Status CheckRenderFlags(const Flags& f) {
  if (absl::Status s = CheckRawFlags(f); !s.ok()) return s;
  const std::string mode = f.Get("mode");
  std::vector<absl::Status> checks = {
      Exclusive(f, "materials", {"transfer"},
                "surfaces mode takes --materials, dvr mode --transfer"),
      Exclusive(f, "preset", {"materials", "transfer"},
                "--preset stands for the classification"),
      // --zoom goes with either: it narrows the field of view of an explicit
      // view as it does an orbit's.
      Exclusive(f, "eye", {"azimuth", "elevation"},
                "a view is explicit (--eye, --target) or an orbit (--azimuth, --elevation)"),
      Exclusive(f, "target", {"azimuth", "elevation"},
                "a view is explicit (--eye, --target) or an orbit (--azimuth, --elevation)"),
      Exclusive(f, "root", {"local", "rings", "threads"},
                "--root renders on a running cluster, whose workers and rings are its own"),
  };
  for (const absl::Status& s : checks) {
    if (!s.ok()) return s;
  }
  if (f.Has("up") && !f.Has("eye")) {
    return absl::InvalidArgumentError("--up belongs to an explicit view: give --eye and --target");
  }
  if (f.Get("projection") == "orthographic" && f.Has("fov")) {
    return absl::InvalidArgumentError(
        "--fov and --projection orthographic contradict each other: an orthographic camera has "
        "no field of view (--zoom sets its extent)");
  }
  bool dvr = mode.empty() ? f.Has("transfer") : mode == "dvr";
  if (mode.empty() && f.Has("preset")) {
    // A preset without materials (a colormap) is for dvr.
    dvr = true;
    for (const PresetInfo& p : ListPresets()) {
      if (p.name == f.Get("preset") && p.surfaces) dvr = false;
    }
  }
  if (mode == "surfaces" && f.Has("transfer")) {
    return absl::InvalidArgumentError("--mode surfaces and --transfer contradict each other: "
                                      "surfaces mode takes --materials");
  }
  if (mode == "dvr" && f.Has("materials")) {
    return absl::InvalidArgumentError("--mode dvr and --materials contradict each other: dvr "
                                      "mode takes --transfer");
  }
  for (const char* surfaces_only : {"shadows", "surface"}) {
    if (dvr && f.Has(surfaces_only)) {
      return absl::InvalidArgumentError(
          absl::StrCat("--", surfaces_only, " is for surfaces mode; dvr mode would ignore it"));
    }
  }
  if (!dvr && f.Has("step")) {
    return absl::InvalidArgumentError("--step is dvr's sample step; surfaces mode would ignore it");
  }
  if (f.Has("local") && f.Get("local") == "0") {
    for (const char* cluster_only : {"rings", "balance", "balance-grid", "balance-rule"}) {
      if (f.Has(cluster_only)) {
        return absl::InvalidArgumentError(absl::StrCat(
            "--", cluster_only, " is for a cluster; --local 0 renders in this process"));
      }
    }
  }
  return absl::OkStatus();
}

// The directory an image will be written to must exist: transtick creates
// none (a typo would otherwise leave a tree of directories behind).
absl::Status CheckOutputDirectory(const std::string& out) {
  const std::filesystem::path dir = std::filesystem::path(out).parent_path();
  std::error_code ec;
  if (!dir.empty() && !std::filesystem::is_directory(dir, ec)) {
    return absl::NotFoundError(
        absl::StrCat("--out: directory '", dir.string(), "' does not exist (transtick creates none)"));
  }
  return absl::OkStatus();
}

int Render(int argc, char** argv) {
  auto fail = [](const absl::Status& s) { return Fail("render", s); };
  int exit = 0;
  auto flags = ParseCommand(argc, argv, kRenderDoc, &exit);
  if (!flags) return exit;
  if (absl::Status s = CheckRenderFlags(*flags); !s.ok()) return fail(s);
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return fail(s);

  // Everything about the request is checked before the volume is read.
  // --preset NAME stands for --materials or --transfer (presets.h).
  const bool preset = flags->Has("preset");
  std::string default_mode = flags->Has("transfer") ? "dvr" : "surfaces";
  if (preset) {
    v1::Dataset probe;
    probe.mutable_preset()->set_name(flags->Get("preset"));
    auto resolved = ResolvePreset(probe, {0.0f, 1.0f});
    if (!resolved.ok()) return fail(absl::InvalidArgumentError(
        absl::StrCat("--preset: ", resolved.status().message())));
    default_mode = resolved->has_materials() ? "surfaces" : "dvr";
  }
  std::string mode_name = flags->Get("mode", default_mode);
  if (mode_name != "surfaces" && mode_name != "dvr") {
    return fail(absl::InvalidArgumentError("--mode must be surfaces or dvr"));
  }
  const bool dvr = mode_name == "dvr";
  if (!preset && !dvr && !flags->Has("materials")) {
    return fail(absl::InvalidArgumentError("surfaces mode needs --materials FILE or --preset NAME"));
  }
  if (!preset && dvr && !flags->Has("transfer")) {
    return fail(absl::InvalidArgumentError("dvr mode needs --transfer FILE or --preset NAME"));
  }
  auto view = ViewFromFlags(*flags);
  if (!view.ok()) return fail(view.status());
  if (absl::Status s = CheckOutputDirectory(view->output()); !s.ok()) return fail(s);
  if (!flags->Has("volume")) return fail(absl::InvalidArgumentError("--volume FILE is required"));
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  auto local = flags->GetInt("local", cores);
  auto rings = ParseRings(flags->Has("rings") ? flags->Get("rings") : "1");
  if (!local.ok()) return fail(local.status());
  if (!rings.ok()) return fail(rings.status());
  if (*local < 0 || *local > 64)
    return fail(absl::InvalidArgumentError("--local must be in [0, 64]"));

  v1::Dataset dataset;
  Classification classification;
  TransferFunction transfer;
  const std::string settings_file = flags->Get(dvr ? "transfer" : "materials");
  absl::StatusOr<std::string> text;
  if (!preset) {
    text = ReadTextFile(settings_file);
    if (!text.ok()) return fail(text.status());
  }
  // --surface overrides the materials' or the preset's surface model
  // (CheckRenderFlags has refused it for dvr).
  v1::SurfaceModel surface = v1::SURFACE_DEFAULT;
  if (flags->Has("surface")) {
    auto s = ParseEnum<v1::SurfaceModel>(flags->Get("surface"), "--surface");
    if (!s.ok() || *s == v1::SURFACE_DEFAULT) {
      return fail(absl::InvalidArgumentError("--surface must be smooth or voxel"));
    }
    surface = *s;
  }
  if (preset) {
    dataset.mutable_preset()->set_name(flags->Get("preset"));
    dataset.mutable_preset()->set_mode(dvr ? v1::DVR : v1::SURFACES);
    dataset.mutable_preset()->set_surface(surface);
    if (auto r = ResolvePreset(dataset, {0.0f, 1.0f}); !r.ok()) {
      return fail(absl::InvalidArgumentError(absl::StrCat("--preset: ", r.status().message())));
    }
  } else if (dvr) {
    if (auto s = ParseJson(*text, settings_file, dataset.mutable_transfer()); !s.ok())
      return fail(s);
    auto tf = ToTransferFunction(dataset.transfer());
    if (!tf.ok())
      return fail(
          absl::InvalidArgumentError(absl::StrCat(settings_file, ": ", tf.status().message())));
    transfer = *std::move(tf);
  } else {
    if (auto s = ParseJson(*text, settings_file, dataset.mutable_materials()); !s.ok())
      return fail(s);
    if (surface != v1::SURFACE_DEFAULT) dataset.mutable_materials()->set_surface(surface);
    auto c = ToClassification(dataset.materials());
    if (!c.ok())
      return fail(
          absl::InvalidArgumentError(absl::StrCat(settings_file, ": ", c.status().message())));
    classification = *std::move(c);
  }
  if (*local == 0 && !flags->Has("root")) {
    return RenderInProcess(*flags, *view, dvr, classification, transfer, dataset);
  }

  // On a cluster: an embedded one (--local N), or a running one (--root).
  const std::string volume = flags->Get("volume");
  std::unique_ptr<LocalCluster> cluster;
  std::string root = flags->Get("root");
  if (root.empty()) {
    std::error_code ec;
    std::filesystem::path abs = std::filesystem::absolute(volume, ec).lexically_normal();
    if (!abs.has_filename()) abs = abs.parent_path();  // "series/": a DICOM directory
    // "DIR#UID": one series of a DICOM directory.
    const std::optional<SeriesPath> series = ParseSeriesPath(abs.string());
    if (!std::filesystem::is_regular_file(abs, ec) && !std::filesystem::is_directory(abs, ec) &&
        !(series && std::filesystem::is_directory(series->dir, ec))) {
      return fail(absl::NotFoundError(absl::StrCat(volume, ": cannot open")));
    }
    LocalCluster::Options co;
    co.workers = *local;
    co.rings = *rings;
    // Each worker runs as its daemon would: one tracer thread per core. On
    // one machine the workers then share the cores as their loads need,
    // where a fixed share each would leave a core idle beside a busy slab.
    auto threads = flags->GetInt("threads", cores);
    if (!threads.ok()) return fail(threads.status());
    if (*threads < 1 || *threads > 1024) {
      return fail(absl::InvalidArgumentError("--threads must be in [1, 1024]"));
    }
    co.threads_per_worker = *threads;
    co.data_dir = abs.parent_path().string();
    dataset.set_volume(abs.filename().string());
    if (series && !std::filesystem::exists(abs, ec)) {
      // The series' directory is the dataset ("study/#UID" as "study#UID").
      std::filesystem::path d = std::filesystem::path(series->dir).lexically_normal();
      if (!d.has_filename()) d = d.parent_path();
      co.data_dir = d.parent_path().string();
      dataset.set_volume(absl::StrCat(d.filename().string(), "#", series->series));
    }
    auto c = LocalCluster::Start(co);
    if (!c.ok()) return fail(c.status());
    cluster = *std::move(c);
    root = cluster->root_address();
  } else {
    dataset.set_volume(volume);  // relative to the root's data directory
  }
  if (flags->Has("raw-dims")) {
    auto dims = flags->GetDims("raw-dims", 3);
    if (!dims.ok()) return fail(dims.status());
    v1::RawVolume* raw = dataset.mutable_raw();
    for (int d : *dims) raw->add_dims(d);
    raw->set_type(flags->Get("raw-type", "uint8"));
    raw->set_big_endian(flags->Get("raw-endian", "little") == "big");
    if (flags->Has("raw-spacing")) {
      auto sp = flags->GetTriple("raw-spacing");
      if (!sp.ok()) return fail(sp.status());
      for (double x : *sp) raw->add_spacing(x);
    }
    auto skip = flags->GetInt("raw-skip", 0);
    if (!skip.ok()) return fail(skip.status());
    raw->set_header_bytes(static_cast<uint64_t>(std::max(0, *skip)));
  }
  std::string out = view->output();
  if (std::filesystem::path(out).is_relative()) {
    view->set_output((std::filesystem::current_path() / out).string());
  }
  *dataset.add_views() = *view;
  v1::Job job;
  job.set_name("render");
  *job.add_datasets() = dataset;
  auto balance = ParseEnum<v1::BalanceMode>(flags->Get("balance", "off"), "--balance");
  if (!balance.ok()) return fail(balance.status());
  job.set_balance(*balance);
  auto grid = flags->GetInt("balance-grid", 0);  // 0: the root's default
  if (!grid.ok()) return fail(grid.status());
  job.set_balance_grid(*grid);
  auto rule = ParseEnum<v1::BalanceRule>(flags->Get("balance-rule", "cost"), "--balance-rule");
  if (!rule.ok()) return fail(rule.status());
  job.set_balance_rule(*rule);
  ChooseImageEncoding(&job);
  Progress progress(Progress::ForStderr(flags->Has("quiet")));
  WatchOptions wo;
  wo.progress = &progress;
  auto stats = SubmitAndWatch(root, job, wo);
  progress.Finish();
  if (!stats.ok()) return fail(stats.status());
  if (!stats->empty() && !flags->Has("quiet")) {
    PrintClusterFrame(stats->front());
    std::fprintf(stderr, "%s: %dx%d %s on %d workers\n", out.c_str(), view->width(), view->height(),
                 mode_name.c_str(), stats->front().workers_size());
  }
  if (!stats->empty() && flags->Has("stats")) WriteStats(flags->Get("stats"), stats->front());
  return 0;
}

// The stats of a job's frames as a JSON array, for --stats.
void WriteStatsArray(const std::string& path, const std::vector<v1::ClusterFrameStats>& stats) {
  std::ofstream f(path);
  f << "[\n";
  for (size_t i = 0; i < stats.size(); ++i) {
    f << ToJson(stats[i]) << (i + 1 < stats.size() ? ",\n" : "\n");
  }
  f << "]\n";
  if (!f) std::cerr << "transtick: cannot write " << path << "\n";
}

// submit and watch: follow a job to its end, saving its images.
int FollowJob(int argc, char** argv, const CommandDoc& doc, const char* command, bool submit) {
  int exit = 0;
  auto flags = ParseCommand(argc, argv, doc, &exit);
  if (!flags) return exit;
  auto fail = [command](const absl::Status& s) { return Fail(command, s); };
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return fail(s);
  if (!flags->Has("root")) return fail(absl::InvalidArgumentError("--root HOST:PORT is required"));
  const std::string out_dir = flags->Get("out-dir", ".");
  Progress progress(Progress::ForStderr(flags->Has("quiet")));
  // --out-dir names a directory to write into: made if missing (one level,
  // said aloud); the directories of the job's own paths must exist.
  std::error_code ec;
  if (!std::filesystem::exists(out_dir, ec)) {
    if (!std::filesystem::create_directory(out_dir, ec)) {
      return fail(absl::NotFoundError(absl::StrCat("--out-dir: cannot create '", out_dir,
                                                   "': ", ec ? ec.message() : "it exists")));
    }
    progress.Say(absl::StrCat("created directory ", out_dir));
  }
  WatchOptions wo;
  wo.out_dir = out_dir;
  wo.progress = &progress;
  absl::StatusOr<std::vector<v1::ClusterFrameStats>> stats;
  if (submit) {
    auto job = LoadJobFile(flags->positional()[0]);
    if (!job.ok()) return fail(job.status());
    if (absl::Status s = CheckOutputDirectories(*job, out_dir); !s.ok()) return fail(s);
    ChooseImageEncoding(&*job);
    stats = SubmitAndWatch(flags->Get("root"), *job, wo);
  } else {
    if (absl::Status s = CheckOutputDirectories(v1::Job(), out_dir); !s.ok()) return fail(s);
    stats = WatchJob(flags->Get("root"), flags->positional()[0], wo);
  }
  progress.Finish();
  if (!stats.ok()) return fail(stats.status());
  if (!flags->Has("quiet")) {
    for (const auto& s : *stats) PrintClusterFrame(s);
  }
  if (flags->Has("stats")) WriteStatsArray(flags->Get("stats"), *stats);
  return 0;
}

int StatusCommand(int argc, char** argv) {
  int exit = 0;
  auto flags = ParseCommand(argc, argv, kStatusDoc, &exit);
  if (!flags) return exit;
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return Fail("status", s);
  if (!flags->Has("root"))
    return Fail("status", absl::InvalidArgumentError("--root HOST:PORT is required"));
  auto stub = v1::Root::NewStub(MakeChannel(flags->Get("root"), Role::kRoot));
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(10));
  v1::StatusReply reply;
  grpc::Status s = stub->Status(&ctx, v1::StatusRequest(), &reply);
  if (!s.ok()) return Fail("status", FromGrpc(s));
  if (reply.rings() == kAutoRings) {
    std::printf("%d workers, rings auto\n", reply.workers_size());
  } else {
    std::printf("%d workers, %d ring(s)\n", reply.workers_size(), reply.rings());
  }
  for (const auto& w : reply.workers()) {
    std::printf("  worker %s at %s, %d threads", w.id().c_str(), w.address().c_str(), w.threads());
    if (w.cpus() > 0 && w.machine_cpus() > 0) {
      std::printf(" on %.4g of its machine's %d CPUs", w.cpus(), w.machine_cpus());
    }
    if (w.memory_bytes() > 0) {
      std::printf(", %.0f MB%s", w.memory_bytes() / 1048576.0,
                  w.memory_shared() ? " of its host's" : "");
    }
    if (w.ring() >= 0) {
      std::printf(", ring %d, slab [%d, %d)", w.ring(), w.slab_begin(), w.slab_end());
    }
    std::printf("\n");
  }
  for (const auto& j : reply.jobs()) {
    // Names are other clients' strings (an admin sees every job): escaped,
    // they cannot move the cursor or forge a line.
    std::printf("%-10s %-10s %3d/%-3d %-8s %s%s%s\n", j.job_id().c_str(),
                v1::JobState_Name(j.state()).c_str(), j.frames_done(), j.frames_total(),
                j.owner().c_str(), Printable(j.name()).c_str(),
                j.error().empty() ? "" : "  error: ", Printable(j.error()).c_str());
  }
  return 0;
}

// "6.9 MiB", "512 KiB", "300 B"
std::string ShowBytes(uint64_t n) {
  if (n >= uint64_t{1} << 30) return absl::StrFormat("%.1f GiB", n / 1073741824.0);
  if (n >= uint64_t{1} << 20) return absl::StrFormat("%.1f MiB", n / 1048576.0);
  if (n >= uint64_t{1} << 10) return absl::StrFormat("%.0f KiB", n / 1024.0);
  return absl::StrCat(n, " B");
}

int VolumesCommand(int argc, char** argv) {
  auto fail = [](const absl::Status& s) { return Fail("volumes", s); };
  int exit = 0;
  auto flags = ParseCommand(argc, argv, kVolumesDoc, &exit);
  if (!flags) return exit;
  if (flags->Has("root") == flags->Has("data-dir")) {
    return fail(absl::InvalidArgumentError("give one of --root HOST:PORT and --data-dir DIR"));
  }
  v1::VolumesReply reply;
  if (flags->Has("root")) {
    if (absl::Status s = UseSecurity(*flags); !s.ok()) return fail(s);
    auto stub = v1::Root::NewStub(MakeChannel(flags->Get("root"), Role::kRoot));
    grpc::ClientContext ctx;
    ctx.set_deadline(Deadline(60));
    grpc::Status s = stub->Volumes(&ctx, v1::VolumesRequest(), &reply);
    if (!s.ok()) return fail(FromGrpc(s));
  } else {
    auto dir = ConfinedDir::Open(flags->Get("data-dir"));
    if (!dir.ok()) return fail(dir.status());
    auto listed = ListVolumes(**dir);
    if (!listed.ok()) return fail(listed.status());
    reply = *std::move(listed);
  }
  size_t width = 0;
  for (const auto& v : reply.volumes()) width = std::max(width, v.path().size());
  for (const auto& v : reply.volumes()) {
    // The root's strings: escaped, they cannot move the cursor.
    std::string line = absl::StrFormat("%-*s %10s", static_cast<int>(width), Printable(v.path()),
                                       ShowBytes(v.bytes()));
    if (v.series()) {
      absl::StrAppend(&line, "  DICOM", v.description().empty() ? "" : ": ",
                      Printable(v.description()));
    }
    if (!v.error().empty()) absl::StrAppend(&line, "  cannot open: ", Printable(v.error()));
    std::printf("%s\n", line.c_str());
  }
  if (reply.volumes().empty()) std::printf("no volumes\n");
  if (reply.truncated()) {
    std::fprintf(stderr,
                 "transtick volumes: the listing stopped at its bounds; there is more "
                 "(docs/formats.md#volumes-listing)\n");
  }
  return 0;
}

int CancelCommand(int argc, char** argv) {
  int exit = 0;
  auto flags = ParseCommand(argc, argv, kCancelDoc, &exit);
  if (!flags) return exit;
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return Fail("cancel", s);
  if (!flags->Has("root")) {
    return Fail("cancel", absl::InvalidArgumentError("--root HOST:PORT is required"));
  }
  auto stub = v1::Root::NewStub(MakeChannel(flags->Get("root"), Role::kRoot));
  grpc::ClientContext ctx;
  ctx.set_deadline(Deadline(10));
  v1::JobRef ref;
  ref.set_job_id(flags->positional()[0]);
  v1::CancelReply reply;
  grpc::Status s = stub->Cancel(&ctx, ref, &reply);
  if (!s.ok()) return Fail("cancel", FromGrpc(s));
  std::printf("%s: %s\n", ref.job_id().c_str(),
              reply.cancelled() ? "cancelled" : "already finished");
  return 0;
}

// Exit 0 when every daemon at --addr reports SERVING (container probes), with
int PresetsCommand(int argc, char** argv) {
  int exit = 0;
  if (!ParseCommand(argc, argv, kPresetsDoc, &exit)) return exit;
  for (const PresetInfo& p : ListPresets()) {
    std::string modes = p.surfaces && p.dvr ? "surfaces, dvr" : p.surfaces ? "surfaces" : "dvr";
    std::printf("%-14s %-15s %s%s\n", p.name.c_str(), modes.c_str(), p.description.c_str(),
                p.relative ? " (relative to the volume's range)" : "");
  }
  return 0;
}

// `text` for a URL's query: letters, digits and -._~/ as they are, every
// other byte as %XX.
std::string UrlEncode(const std::string& text) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string out;
  for (unsigned char c : text) {
    if (std::isalnum(c) || c == '-' || c == '.' || c == '_' || c == '~' || c == '/') {
      out += static_cast<char>(c);
    } else {
      out += '%';
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  return out;
}

// The viewer: a gateway (services/web) in front of an embedded cluster or
// --root, until SIGINT or SIGTERM.
int View(int argc, char** argv) {
  auto fail = [](const absl::Status& s) { return Fail("view", s); };
  int exit = 0;
  auto flags = ParseCommand(argc, argv, kViewDoc, &exit);
  if (!flags) return exit;
  for (const char* f : {"data-dir", "local", "rings", "threads"}) {
    if (flags->Has("root") && flags->Has(f)) {
      return fail(absl::InvalidArgumentError(absl::StrCat(
          "--root and --", f, " contradict each other: --", f, " is of the embedded cluster")));
    }
  }
  if (flags->Has("tls-ca") && !flags->Has("root")) {
    return fail(absl::InvalidArgumentError(
        "--tls-ca is for a --root with TLS; the embedded cluster runs on loopback"));
  }
  auto security = SecurityFromFlags(*flags, /*daemon=*/false);
  if (!security.ok()) return fail(security.status());
  security->token.clear();  // each browser sends its own
  SetSecurity(*std::move(security));
  BlockTerminationSignals();  // before any thread starts

  std::string volume = flags->Get("volume");
  std::string data_dir = flags->Get("data-dir");
  if (data_dir.empty() && !volume.empty() && !flags->Has("root")) {
    const std::filesystem::path p(volume);
    data_dir = p.has_parent_path() ? p.parent_path().string() : ".";
    volume = p.filename().string();
  }
  if (data_dir.empty()) {
    const char* env = std::getenv("TRANSTICK_DATA_DIR");
    data_dir = env != nullptr && *env != '\0' ? env : ".";
  }
  std::unique_ptr<LocalCluster> cluster;
  std::string root = flags->Get("root");
  if (root.empty()) {
    const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    LocalCluster::Options co;
    auto local = flags->GetInt("local", cores);
    auto rings = ParseRings(flags->Has("rings") ? flags->Get("rings") : "1");
    auto threads = flags->GetInt("threads", cores);
    if (!rings.ok()) return fail(rings.status());
    for (const auto* v : {&local, &threads}) {
      if (!v->ok()) return fail(v->status());
    }
    if (*local < 1 || *local > 64) {
      return fail(absl::InvalidArgumentError("--local must be in [1, 64] for the viewer"));
    }
    if (*rings < 1 || *rings > *local) {
      return fail(absl::InvalidArgumentError("--rings must be in [1, --local]"));
    }
    if (*threads < 1 || *threads > 1024) {
      return fail(absl::InvalidArgumentError("--threads must be in [1, 1024]"));
    }
    if (!std::filesystem::is_directory(data_dir)) {
      return fail(absl::NotFoundError(absl::StrCat("the data directory ", data_dir,
                                                   " is not a directory")));
    }
    co.workers = *local;
    co.rings = *rings;
    co.threads_per_worker = *threads;
    co.data_dir = data_dir;
    auto c = LocalCluster::Start(co);
    if (!c.ok()) return fail(c.status());
    cluster = *std::move(c);
    root = cluster->root_address();
  }
  WebOptions wo;
  wo.root = root;
  wo.listen = flags->Get("listen", "127.0.0.1:8080");
  wo.https_cert = flags->Get("https-cert");
  wo.https_key = flags->Get("https-key");
  wo.static_dir = flags->Get("static-dir");
  auto gateway = WebGateway::Start(wo);
  if (!gateway.ok()) return fail(gateway.status());
  std::string url = (*gateway)->url();
  if (!volume.empty()) {
    std::string preset = flags->Get("preset");
    absl::StrAppend(&url, "?volume=", UrlEncode(volume));
    if (!preset.empty()) absl::StrAppend(&url, "&preset=", UrlEncode(preset));
  }
  std::cout << "transtick view: root " << root << "\n"
            << "transtick view: " << url << std::endl;
  const int sig = WaitForSignal();
  std::cerr << "transtick view: signal " << sig << ", stopping\n";
  gateway->reset();
  cluster.reset();
  return 0;
}

// one line per daemon: its state on stdout, or why it could not be asked on
// stderr.
int Health(int argc, char** argv) {
  using grpc::health::v1::HealthCheckResponse;
  int exit = 0;
  auto flags = ParseCommand(argc, argv, kHealthDoc, &exit);
  if (!flags) return exit;
  if (absl::Status s = UseSecurity(*flags); !s.ok()) return Fail("health", s);
  const std::string role_name = flags->Get("role", "root");
  std::optional<Role> role;
  for (Role r : {Role::kRoot, Role::kWorker, Role::kDisplay}) {
    if (RoleName(r) == absl::StrCat("transtick-", role_name)) role = r;
  }
  if (!role) {
    return Fail("health", absl::InvalidArgumentError("--role must be root, worker or display"));
  }
  auto timeout = flags->GetDouble("timeout", 3);
  if (!timeout.ok()) return Fail("health", timeout.status());
  if (*timeout <= 0)
    return Fail("health", absl::InvalidArgumentError("--timeout must be positive"));
  std::vector<std::string> addresses = absl::StrSplit(flags->Get("addr", "127.0.0.1:7000"), ',');
  for (const std::string& address : addresses) {
    if (address.empty()) {
      return Fail("health", absl::InvalidArgumentError("--addr: an empty address"));
    }
  }
  bool all_serving = true;
  for (const std::string& address : addresses) {
    auto status = CheckHealth(address, *role, *timeout);
    if (!status.ok()) {
      all_serving = false;
      const absl::Status& e = status.status();
      std::string why;
      if (absl::IsUnavailable(e)) {
        why = absl::StrCat("no daemon answers (", e.message(), ")");
      } else if (absl::IsDeadlineExceeded(e)) {
        why = absl::StrCat("no answer within ", *timeout, " s");
      } else if (absl::IsUnimplemented(e)) {
        why = "it does not serve the grpc.health.v1 health service";
      } else {
        why = absl::StrCat(absl::StatusCodeToString(e.code()), ": ", e.message());
      }
      std::fprintf(stderr, "transtick health: %s: %s\n", address.c_str(), why.c_str());
      continue;
    }
    std::printf("%s: %s\n", address.c_str(),
                HealthCheckResponse::ServingStatus_Name(*status).c_str());
    all_serving &= *status == HealthCheckResponse::SERVING;
  }
  return all_serving ? 0 : 1;
}

}  // namespace
}  // namespace transtick

int main(int argc, char** argv) {
  // The embedded cluster's daemons allocate as the real ones do.
  transtick::TuneHeap();
  transtick::UseReleaseLocking();
  // The embedded cluster logs only warnings unless asked for more.
  spdlog::set_level(spdlog::level::warn);
  if (const char* level = std::getenv("TRANSTICK_LOG_LEVEL")) {
    spdlog::set_level(spdlog::level::from_str(level));
  }
  const std::string cmd = argc > 1 ? argv[1] : "help";
  using namespace transtick;
  if (cmd == "render") return Render(argc, argv);
  if (cmd == "info") return Info(argc, argv);
  if (cmd == "submit") return FollowJob(argc, argv, kSubmitDoc, "submit", /*submit=*/true);
  if (cmd == "watch") return FollowJob(argc, argv, kWatchDoc, "watch", /*submit=*/false);
  if (cmd == "status") return StatusCommand(argc, argv);
  if (cmd == "cancel") return CancelCommand(argc, argv);
  if (cmd == "health") return Health(argc, argv);
  if (cmd == "view") return View(argc, argv);
  if (cmd == "presets") return PresetsCommand(argc, argv);
  if (cmd == "volumes") return VolumesCommand(argc, argv);
  if (cmd == "version" || cmd == "--version") {
    int exit = 0;
    if (cmd == "version" && !ParseCommand(argc, argv, kVersionDoc, &exit)) return exit;
    if (cmd == "--version" && argc > 2) {
      std::cerr << "transtick: --version takes no arguments\n";
      return 2;
    }
    std::cout << VersionText() << "\n";
    return 0;
  }
  if (cmd == "help" || cmd == "--help" || cmd == "-h") {
    if (argc == 3) {  // transtick help COMMAND
      for (const CommandDoc* doc : {&kRenderDoc, &kInfoDoc, &kSubmitDoc, &kWatchDoc, &kStatusDoc,
                                    &kCancelDoc, &kHealthDoc, &kVersionDoc, &kViewDoc,
                                    &kPresetsDoc}) {
        if (doc->name == absl::StrCat("transtick ", argv[2])) {
          std::cout << Usage(*doc);
          return 0;
        }
      }
    }
    if (argc > 2 && argc != 3) {
      std::cerr << "transtick: help takes at most one command\n";
      return 2;
    }
    if (argc == 3) {
      std::cerr << "transtick: no command '" << argv[2] << "'\n" << kUsage;
      return 2;
    }
    std::cout << kUsage;
    return 0;
  }
  std::cerr << "transtick: unknown command '" << cmd << "'\n" << kUsage;
  return 2;
}
