#include "worker_service.h"

#include <spdlog/spdlog.h>

#include <bit>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "convert.h"
#include "daemon.h"
#include "transtick/ray_codec.h"

namespace transtick {
namespace {

grpc::Status Invalid(const std::string& message) {
  return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, message);
}

absl::StatusOr<std::shared_ptr<const Scene>> AssembleSlab(const v1::SlabHeader& h,
                                                          std::vector<std::string> blocks,
                                                          std::string scalar_bytes) {
  if (h.dims_size() != 3 || h.spacing_size() != 3 || h.value_range_size() != 2) {
    return absl::InvalidArgumentError("slab header: dims, spacing and value_range incomplete");
  }
  std::array<int, 3> dims = {h.dims(0), h.dims(1), h.dims(2)};
  const bool dvr = h.mode() == "dvr";
  if (!dvr && h.mode() != "surfaces") {
    return absl::InvalidArgumentError(absl::StrCat("slab header: unknown mode '", h.mode(), "'"));
  }
  Classification classification;
  TransferFunction transfer;
  int max_material = 1;
  if (dvr) {
    auto tf = ToTransferFunction(h.transfer());
    if (!tf.ok()) return tf.status();
    transfer = *std::move(tf);
  } else {
    auto c = ToClassification(h.materials());
    if (!c.ok()) return c.status();
    classification = *std::move(c);
    max_material = static_cast<int>(classification.materials.size());
  }
  auto sticks = Sticks::FromBlocks(dims, h.y_begin(), h.y_end(), max_material, blocks);
  if (!sticks.ok()) return sticks.status();
  auto bricks =
      BrickMap::FromBytes(dims, std::vector<uint8_t>(h.brick_map().begin(), h.brick_map().end()));
  if (!bricks.ok()) return bricks.status();
  if (scalar_bytes.size() % 4 != 0) {
    return absl::InvalidArgumentError("slab scalars: not a whole number of floats");
  }
  std::vector<float> scalars(scalar_bytes.size() / 4);
  DecodeFloats(scalar_bytes, scalars.data());
  auto scene =
      Scene::FromParts(dvr ? RenderMode::kDvr : RenderMode::kSurfaces, dims,
                       {h.spacing(0), h.spacing(1), h.spacing(2)},
                       {h.value_range(0), h.value_range(1)}, *std::move(sticks), std::move(scalars),
                       *std::move(bricks), std::move(classification), std::move(transfer));
  if (!scene.ok()) return scene.status();
  return std::shared_ptr<const Scene>(std::make_shared<Scene>(*std::move(scene)));
}

}  // namespace

WorkerService::WorkerService(WorkerOptions options) : options_(std::move(options)) {}

WorkerService::~WorkerService() { CancelAll(); }

void WorkerService::set_address(const std::string& address) {
  std::lock_guard<std::mutex> lock(mu_);
  options_.address = address;
}

void WorkerService::CancelAll() {
  std::map<uint64_t, std::shared_ptr<Frame>> frames;
  {
    std::lock_guard<std::mutex> lock(mu_);
    frames.swap(frames_);
  }
  for (auto& [id, f] : frames) f->End(/*cancel=*/true);
}

grpc::Status WorkerService::LoadSlab(grpc::ServerContext* ctx,
                                     grpc::ServerReader<v1::SlabChunk>* reader,
                                     v1::LoadReply* reply) {
  v1::SlabChunk chunk;
  if (!reader->Read(&chunk) || !chunk.has_header()) {
    return Invalid("LoadSlab: the first message must carry the slab header");
  }
  const v1::SlabHeader header = chunk.header();
  if (header.dataset_key().empty()) return Invalid("LoadSlab: empty dataset_key");
  if (header.scalar_count() * 4 > options_.max_slab_bytes) {
    return grpc::Status(
        grpc::StatusCode::RESOURCE_EXHAUSTED,
        absl::StrCat("LoadSlab: ", header.scalar_count() * 4,
                     " bytes of scalars exceed this worker's limit of ", options_.max_slab_bytes));
  }
  std::vector<std::string> blocks;
  std::string scalars;
  scalars.reserve(header.scalar_count() * 4);
  do {
    for (auto& b : *chunk.mutable_blocks()) blocks.push_back(std::move(b));
    if (scalars.size() + chunk.scalars().size() > header.scalar_count() * 4) {
      return Invalid("LoadSlab: more scalars than the header announced");
    }
    scalars += chunk.scalars();
  } while (reader->Read(&chunk));
  if (scalars.size() != header.scalar_count() * 4) {
    return Invalid(absl::StrCat("LoadSlab: ", scalars.size() / 4, " scalars arrived, header said ",
                                header.scalar_count()));
  }
  auto scene = AssembleSlab(header, std::move(blocks), std::move(scalars));
  if (!scene.ok()) return ToGrpc(scene.status());
  reply->set_memory_bytes((*scene)->MemoryBytes());
  spdlog::info("loaded {} slab [{}, {}): {:.1f} MB", header.dataset_key(), header.y_begin(),
               header.y_end(), (*scene)->MemoryBytes() / 1e6);
  std::lock_guard<std::mutex> lock(mu_);
  datasets_[header.dataset_key()] = *std::move(scene);
  return grpc::Status::OK;
}

grpc::Status WorkerService::Evict(grpc::ServerContext*, const v1::DatasetRef* req, v1::FrameAck*) {
  std::lock_guard<std::mutex> lock(mu_);
  if (req->dataset_key().empty()) {
    datasets_.clear();
  } else {
    datasets_.erase(req->dataset_key());
  }
  return grpc::Status::OK;
}

grpc::Status WorkerService::PrepareFrame(grpc::ServerContext*, const v1::FrameSpec* spec,
                                         v1::FrameAck*) {
  std::shared_ptr<const Scene> scene;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = datasets_.find(spec->dataset_key());
    if (it == datasets_.end()) {
      return grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                          absl::StrCat("dataset ", spec->dataset_key(), " is not loaded here"));
    }
    scene = it->second;
    if (frames_.count(spec->frame_id())) {
      return grpc::Status(grpc::StatusCode::ALREADY_EXISTS,
                          absl::StrCat("frame ", spec->frame_id(), " is already prepared"));
    }
  }
  const int n = spec->cuts_size() - 1;
  if (n < 1 || spec->index() < 0 || spec->index() >= n ||
      spec->cuts(spec->index()) != scene->y_begin() ||
      spec->cuts(spec->index() + 1) != scene->y_end()) {
    return Invalid(absl::StrCat("frame ", spec->frame_id(), ": slab ", spec->index(),
                                " of the cuts does not match the loaded slab [", scene->y_begin(),
                                ", ", scene->y_end(), ")"));
  }
  auto cam_spec = ToCameraSpec(spec->view());
  if (!cam_spec.ok()) return ToGrpc(cam_spec.status());
  const auto& d = scene->dims();
  const auto& sp = scene->spacing();
  auto camera = Camera::Create(*cam_spec, Vec3{d[0] * sp[0], d[1] * sp[1], d[2] * sp[2]});
  if (!camera.ok()) return ToGrpc(camera.status());
  if (spec->row_step() < 1 || spec->row_begin() < 0 || spec->row_end() > camera->height() ||
      spec->display().empty()) {
    return Invalid("frame: bad row range or no display");
  }
  FrameOptions fo;
  fo.threads = options_.threads;
  auto frame = std::make_shared<Frame>(*spec, std::move(scene), *std::move(camera), fo);
  std::lock_guard<std::mutex> lock(mu_);
  frames_[spec->frame_id()] = std::move(frame);
  frames_cv_.notify_all();
  return grpc::Status::OK;
}

std::shared_ptr<Frame> WorkerService::FindFrame(uint64_t id) {
  std::unique_lock<std::mutex> lock(mu_);
  // A neighbour's stream may race the root's PrepareFrame by a little.
  frames_cv_.wait_for(lock, std::chrono::seconds(5), [&] { return frames_.count(id) > 0; });
  auto it = frames_.find(id);
  return it == frames_.end() ? nullptr : it->second;
}

grpc::Status WorkerService::RunFrame(grpc::ServerContext*, const v1::FrameRef* req, v1::FrameAck*) {
  std::shared_ptr<Frame> frame;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = frames_.find(req->frame_id());
    if (it != frames_.end()) frame = it->second;
  }
  if (!frame) {
    return grpc::Status(grpc::StatusCode::NOT_FOUND,
                        absl::StrCat("frame ", req->frame_id(), " was not prepared"));
  }
  return ToGrpc(frame->Start());
}

grpc::Status WorkerService::EndFrame(grpc::ServerContext*, const v1::FrameRef* req,
                                     v1::WorkerFrameStats* reply) {
  std::shared_ptr<Frame> frame;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = frames_.find(req->frame_id());
    if (it == frames_.end()) {
      return grpc::Status(grpc::StatusCode::NOT_FOUND,
                          absl::StrCat("frame ", req->frame_id(), " is not running here"));
    }
    frame = it->second;
    frames_.erase(it);
  }
  *reply = frame->End(req->cancel());
  std::lock_guard<std::mutex> lock(mu_);
  reply->set_id(options_.id);
  reply->set_address(options_.address);
  return grpc::Status::OK;
}

grpc::Status WorkerService::Rays(grpc::ServerContext*,
                                 grpc::ServerReaderWriter<v1::RayBatch, v1::RayBatch>* stream) {
  v1::RayBatch first;
  if (!stream->Read(&first)) return Invalid("Rays: the stream closed before its first batch");
  std::shared_ptr<Frame> frame = FindFrame(first.frame_id());
  if (!frame) {
    return grpc::Status(grpc::StatusCode::NOT_FOUND,
                        absl::StrCat("Rays: frame ", first.frame_id(), " is not prepared here"));
  }
  return frame->ServeLeft(stream);
}

}  // namespace transtick
