// The client side of the cluster: submitting jobs and watching them, saving
// images. The embedded cluster of `transtick render --local N` is
// services/local/local_cluster.h.
#ifndef TRANSTICK_CLI_CLIENT_H_
#define TRANSTICK_CLI_CLIENT_H_

#include <chrono>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "cluster.grpc.pb.h"
#include "cluster.pb.h"
#include "transtick/framebuffer.h"
#include "grpc/health/v1/health.pb.h"
#include "security.h"

namespace transtick {

class Progress;

struct WatchOptions {
  std::string out_dir;           // where images with relative output paths go
  Progress* progress = nullptr;  // told of progress, saved frames, warnings; null: silent
  // How long to keep trying to reach the root again after the watch
  // stream broke, counted from the last event received.
  std::chrono::seconds reconnect{300};
  // Images of views without an output path: out_dir/JOB-dD-vV.png.
};

// A frame's image as its chunks of rows come (docs/formats.md: a frame is
// whole when its chunks cover its height). A row may come more than once:
// from a rendering a resuming watcher asked for again, after the first
// rendering's remaining rows; it holds the same bits. Only rows not yet
// held count toward the whole.
class ImageRows {
 public:
  ImageRows() = default;
  // Holds the image in `spare`, the buffer of a frame saved before
  // (TakeBuffer): a job's frames then reuse one buffer instead of each
  // zeroing and faulting in a fresh one. Its values are overwritten: the
  // image is whole only once every row has come.
  explicit ImageRows(std::vector<float> spare) { image_.rgb = std::move(spare); }
  // Adds `chunk`'s rows (the first chunk sizes the image); DATA_LOSS for a
  // chunk of an impossible size or one that does not fit the image.
  absl::Status Add(const v1::ImageChunk& chunk);
  bool whole() const { return image_.height > 0 && rows_ == image_.height; }
  Image& image() { return image_; }
  std::vector<float> TakeBuffer() { return std::move(image_.rgb); }

 private:
  Image image_;
  std::vector<bool> have_;  // per row
  int rows_ = 0;            // rows held
  bool sized_ = false;      // by the first chunk
};

// Submits `job` to the root; UNAVAILABLE naming the root when it cannot
// be reached.
absl::StatusOr<v1::SubmitReply> SubmitJob(const std::string& root, const v1::Job& job);

// Follows job `job_id` to its end, saving each frame's image to its output
// path (relative paths beneath options.out_dir; a view without one as
// out_dir/JOB-dD-vV.png). Every frame is delivered: those already rendered
// too. When the stream breaks it watches again (the root resumes the job
// from its store and sends the frames not yet saved). Returns the frames'
// statistics, or the job's error. Directories are never created: an output
// whose directory does not exist is an error naming it.
absl::StatusOr<std::vector<v1::ClusterFrameStats>> WatchJob(const std::string& root,
                                                            const std::string& job_id,
                                                            const WatchOptions& options);

// The image encoding a client that writes the job's images to files needs,
// set on `job` when it leaves it to the client (IMAGE_ENCODING_DEFAULT):
// RGB8 when every view's output (or the default, a .png) is an 8-bit format,
// whose files then come out the same from a quarter of the bytes, else
// FLOAT32. An encoding the job names stays.
void ChooseImageEncoding(v1::Job* job);

// SubmitJob, then WatchJob.
absl::StatusOr<std::vector<v1::ClusterFrameStats>> SubmitAndWatch(const std::string& root,
                                                                  const v1::Job& job,
                                                                  const WatchOptions& options);

// Checks, before a job is sent, that every image it will write lands in a
// directory that exists: `out_dir` itself, and the directory of each view's
// output (beneath out_dir when relative). The error names the view and the
// missing directory.
absl::Status CheckOutputDirectories(const v1::Job& job, const std::string& out_dir);

// The client side of an interactive session (docs/formats.md, "Session
// stream"): requests go out from any thread, events come in through Next
// from one thread at a time.
class SessionClient {
 public:
  // What Next returns: a whole frame (its chunks assembled), a ready
  // notice, or the error of one request.
  struct Event {
    uint64_t seq = 0;
    std::optional<v1::SessionReady> ready;
    bool has_frame = false;
    bool preview = false;
    Image image;
    v1::ClusterFrameStats stats;
    std::string error;
  };

  // Opens a session on `dataset` (its views[0] is the first camera), with a
  // preview at 1/preview of the size before each frame (0: none). The first
  // event Next returns is the dataset's ready notice, or the open fails.
  // A `bearer` token is sent with the call (a gateway forwarding its
  // browser's), besides any the process's security sends. Frames travel in
  // `encoding` (docs/formats.md, "Image chunks"); Next gives float images
  // either way, RGB8's as FromByte of each byte.
  static absl::StatusOr<std::unique_ptr<SessionClient>> Open(
      const std::string& root, const v1::Dataset& dataset, int preview = 0,
      const std::string& bearer = "", v1::ImageEncoding encoding = v1::IMAGE_ENCODING_DEFAULT);
  ~SessionClient();

  // A new camera; returns its seq. Thread-safe.
  absl::StatusOr<uint64_t> SetView(const v1::View& view);
  // A new classification (materials for surfaces, transfer for dvr).
  absl::StatusOr<uint64_t> SetMaterials(const v1::MaterialSet& materials);
  absl::StatusOr<uint64_t> SetTransfer(const v1::TransferFunction& transfer);
  // Any of them in one request (a camera and a classification together);
  // its seq is set here.
  absl::StatusOr<uint64_t> Send(v1::SessionRequest request);
  // The next event; the stream's end (the root's status) when there is none.
  absl::StatusOr<Event> Next();
  // Closes this side and waits for the root to end the session.
  absl::Status Close();
  // Ends the session now: a Next in progress returns CANCELLED. Thread-safe.
  void Cancel() { ctx_.TryCancel(); }

 private:
  SessionClient() = default;

  std::unique_ptr<v1::Root::Stub> stub_;
  grpc::ClientContext ctx_;
  std::unique_ptr<grpc::ClientReaderWriter<v1::SessionRequest, v1::SessionEvent>> stream_;
  absl::Mutex mu_;
  uint64_t next_seq_ ABSL_GUARDED_BY(mu_) = 1;
  bool closed_ ABSL_GUARDED_BY(mu_) = false;
  bool finished_ ABSL_GUARDED_BY(mu_) = false;  // the stream's status is in: nothing more to write
  std::map<std::pair<uint64_t, bool>, ImageRows> partial_;  // by (seq, preview)
};

// Reads a job file (protobuf JSON of transtick.v1.Job). A dataset may name
// "materials_file" or "transfer_file" relative to the job file; they are
// read here and sent inline.
absl::StatusOr<v1::Job> LoadJobFile(const std::string& path);

// What the standard health service of the daemon at `address` reports for
// the whole server, decoded from its HealthCheckResponse; or the call's
// error (UNAVAILABLE when nothing answers there, DEADLINE_EXCEEDED after
// `timeout_s` seconds). With TLS, the daemon's certificate must be of `role`.
absl::StatusOr<grpc::health::v1::HealthCheckResponse::ServingStatus> CheckHealth(
    const std::string& address, Role role, double timeout_s);

}  // namespace transtick

#endif  // TRANSTICK_CLI_CLIENT_H_
