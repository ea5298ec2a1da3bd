#include "dicom_decoder.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstring>
#include <ctime>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "dicom_decoder_protocol.h"
#include "module_loader.h"

extern char** environ;

namespace transtick {
namespace {

namespace dd = dicom_decoder;

#ifdef TRANSTICK_DICOM_DECODER_BUILD_PATH
constexpr const char* kBuildPath = TRANSTICK_DICOM_DECODER_BUILD_PATH;
#else
constexpr const char* kBuildPath = nullptr;
#endif

constexpr size_t kSaidBytes = 2048;  // of the decoder's standard error kept
constexpr double kBytesPerSecond = 4 << 20;

int64_t NowNs() {
  timespec ts;
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

int64_t After(double seconds) {
  return NowNs() + static_cast<int64_t>(std::clamp(seconds, 0.0, 1e6) * 1e9);
}

// `text` as one printable line of at most `limit` characters.
std::string Printable(absl::string_view text, size_t limit) {
  std::string s(absl::StripAsciiWhitespace(text));
  if (s.size() > limit) s = s.substr(0, limit - 3) + "...";
  for (char& c : s) {
    if (!absl::ascii_isprint(static_cast<unsigned char>(c))) c = '?';
  }
  return s;
}

// The last line the decoder wrote on its standard error.
std::string LastWords(const std::string& said) {
  absl::string_view s = absl::StripTrailingAsciiWhitespace(said);
  const size_t nl = s.rfind('\n');
  if (nl != absl::string_view::npos) s = s.substr(nl + 1);
  return Printable(s, 300);
}

absl::Status Errno(absl::string_view what) {
  return absl::UnavailableError(absl::StrCat("DICOM decoder: ", what, ": ", std::strerror(errno)));
}

}  // namespace

absl::StatusOr<std::unique_ptr<DicomDecoder>> DicomDecoder::Start(uint64_t max_memory,
                                                                  double seconds) {
  const std::vector<std::string> candidates =
      CompanionCandidates("transtick-dicom-decode", "TRANSTICK_DICOM_DECODER", kBuildPath);
  std::string program;
  for (const std::string& c : candidates) {
    if (::access(c.c_str(), X_OK) == 0) {
      program = c;
      break;
    }
  }
  if (program.empty()) {
    return absl::UnavailableError(
        absl::StrCat("transtick-dicom-decode, which decodes compressed DICOM pixel data, is not "
                     "installed (tried ",
                     absl::StrJoin(candidates, ", "), ")"));
  }
  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) != 0) return Errno("socketpair");
  int ep[2];
  if (::pipe2(ep, O_CLOEXEC) != 0) {
    const absl::Status s = Errno("pipe");
    ::close(sv[0]);
    ::close(sv[1]);
    return s;
  }
  // Its standard input and output the socket, its standard error the pipe,
  // nothing else of ours open; a process group of its own (Stop kills the
  // group); every signal at its default and none blocked, whatever this
  // process set.
  posix_spawn_file_actions_t files;
  posix_spawn_file_actions_init(&files);
  posix_spawn_file_actions_adddup2(&files, sv[1], 0);
  posix_spawn_file_actions_adddup2(&files, sv[1], 1);
  posix_spawn_file_actions_adddup2(&files, ep[1], 2);
  posix_spawn_file_actions_addclosefrom_np(&files, 3);
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  posix_spawnattr_setflags(&attr,
                           POSIX_SPAWN_SETPGROUP | POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  posix_spawnattr_setpgroup(&attr, 0);
  sigset_t none, all;
  sigemptyset(&none);
  sigfillset(&all);
  sigdelset(&all, SIGKILL);
  sigdelset(&all, SIGSTOP);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setsigdefault(&attr, &all);
  // No PATH to run anything by (GDCM runs pvrg-jpeg through the shell
  // when its JPEG decoder fails); the sanitizers' options pass through
  // (in a sanitized build), but not leak checking: what the decoder leaks
  // ends with it, and the check needs ptrace, which its confinement
  // refuses.
  std::vector<std::string> env = {"PATH=/nonexistent"};
  const char* asan = std::getenv("ASAN_OPTIONS");
  env.push_back(absl::StrCat("ASAN_OPTIONS=", asan ? asan : "", asan ? ":" : "", "detect_leaks=0"));
  if (const char* v = std::getenv("UBSAN_OPTIONS"))
    env.push_back(absl::StrCat("UBSAN_OPTIONS=", v));
  std::vector<char*> envp;
  for (std::string& e : env) envp.push_back(e.data());
  envp.push_back(nullptr);
  std::string memory = absl::StrCat("--max-memory=", max_memory);
  char* argv[] = {program.data(), memory.data(), nullptr};
  pid_t pid = -1;
  const int rc = ::posix_spawn(&pid, program.c_str(), &files, &attr, argv, envp.data());
  posix_spawn_file_actions_destroy(&files);
  posix_spawnattr_destroy(&attr);
  ::close(sv[1]);
  ::close(ep[1]);
  if (rc != 0) {
    ::close(sv[0]);
    ::close(ep[0]);
    return absl::UnavailableError(
        absl::StrCat(program, " (the DICOM decoder) cannot be started: ", std::strerror(rc)));
  }
  ::fcntl(sv[0], F_SETFL, O_NONBLOCK);
  ::fcntl(ep[0], F_SETFL, O_NONBLOCK);
  std::unique_ptr<DicomDecoder> d(new DicomDecoder(pid, sv[0], ep[0]));
  char hello[dd::kHelloBytes];
  const Io io = d->Pump(nullptr, 0, hello, sizeof(hello), After(seconds));
  if (io == Io::kTimedOut) {
    d->Stop(0);
    return absl::UnavailableError(
        absl::StrCat(program, " (the DICOM decoder) did not start within ", seconds, " s"));
  }
  if (io == Io::kClosed) {
    const std::string how = d->Stop(1000);
    return absl::UnavailableError(
        absl::StrCat(program, " (the DICOM decoder) ", how, " as it started", d->Said()));
  }
  const std::optional<uint32_t> version = dd::ReadHello(hello);
  if (version != dd::kVersion) {
    d->Stop(0);
    return absl::UnavailableError(absl::StrCat(
        program, " is not this transtick's DICOM decoder (",
        version ? absl::StrCat("protocol version ", *version, ", not ", dd::kVersion) : "no hello",
        ")"));
  }
  return d;
}

DicomDecoder::~DicomDecoder() { Stop(0); }

void DicomDecoder::DrainErrors() {
  char buf[4096];
  while (errors_ >= 0) {
    const ssize_t r = ::read(errors_, buf, sizeof(buf));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0 && errno == EAGAIN) return;
    if (r <= 0) {
      ::close(errors_);
      errors_ = -1;
      return;
    }
    said_.append(buf, static_cast<size_t>(r));
    if (said_.size() > kSaidBytes) said_.erase(0, said_.size() - kSaidBytes);
  }
}

DicomDecoder::Io DicomDecoder::Pump(const char* out, size_t out_n, char* in, size_t in_n,
                                    int64_t deadline) {
  size_t sent = 0, got = 0;
  while (sent < out_n || got < in_n) {
    const bool sending = sent < out_n;
    const ssize_t n = sending ? ::send(socket_, out + sent, out_n - sent, MSG_NOSIGNAL)
                              : ::recv(socket_, in + got, in_n - got, 0);
    if (n > 0) {
      (sending ? sent : got) += static_cast<size_t>(n);
      continue;
    }
    if (n == 0 || (errno != EAGAIN && errno != EINTR)) return Io::kClosed;
    const int64_t left = deadline - NowNs();
    if (left <= 0) return Io::kTimedOut;
    pollfd fds[2] = {{socket_, static_cast<short>(sending ? POLLOUT : POLLIN), 0},
                     {errors_, POLLIN, 0}};
    const int ms = static_cast<int>(std::min<int64_t>(left / 1'000'000 + 1, INT_MAX));
    if (::poll(fds, errors_ >= 0 ? 2 : 1, ms) > 0 && errors_ >= 0 && fds[1].revents != 0) {
      DrainErrors();
    }
  }
  return Io::kDone;
}

std::string DicomDecoder::Stop(int grace_ms) {
  if (stopped_) return "stopped";
  stopped_ = true;
  // Waits (without reaping: its pid, and so its group's id, stays taken
  // until the group is killed) for it to end by itself, reading what it
  // says meanwhile.
  const int64_t end = NowNs() + int64_t{grace_ms} * 1'000'000;
  bool ended = false;
  for (;;) {
    siginfo_t info = {};
    if (::waitid(P_PID, static_cast<id_t>(pid_), &info, WEXITED | WNOHANG | WNOWAIT) != 0) {
      ended = errno != EINTR;  // ECHILD: reaped elsewhere (SIGCHLD ignored)
      if (ended) break;
      continue;
    }
    if (info.si_pid == pid_ || NowNs() >= end) {
      ended = info.si_pid == pid_;
      break;
    }
    pollfd fd = {errors_, POLLIN, 0};
    ::poll(&fd, errors_ >= 0 ? 1 : 0, 10);
    DrainErrors();
  }
  ::kill(-pid_, SIGKILL);  // and whatever it started
  int status = 0;
  pid_t r;
  while ((r = ::waitpid(pid_, &status, 0)) < 0 && errno == EINTR) {
  }
  DrainErrors();
  ::close(socket_);
  if (errors_ >= 0) ::close(errors_);
  errors_ = -1;
  std::string how = "ended";
  if (!ended) {
    how = "was stopped";
  } else if (r == pid_ && WIFSIGNALED(status)) {
    const char* name = sigdescr_np(WTERMSIG(status));
    how =
        absl::StrCat("was killed by signal ", WTERMSIG(status), " (", name ? name : "unknown", ")");
  } else if (r == pid_ && WIFEXITED(status)) {
    how = absl::StrCat("exited with status ", WEXITSTATUS(status));
  }
  return how;
}

std::string DicomDecoder::Said() const {
  const std::string words = LastWords(said_);
  return words.empty() ? "" : absl::StrCat(" (its last words: \"", words, "\")");
}

absl::Status DicomDecoder::Failed(const std::string& path, Io io, double seconds,
                                  const std::string& what) {
  if (io == Io::kTimedOut) {
    Stop(0);
    return absl::DeadlineExceededError(
        absl::StrCat(path, ": decoding its compressed pixel data took longer than ", seconds,
                     " s; the DICOM decoder was stopped"));
  }
  if (io == Io::kClosed) {
    const std::string how = Stop(1000);
    return absl::InvalidArgumentError(absl::StrCat(
        path, ": the DICOM decoder (GDCM, in a process of its own) ", how,
        " while decoding its compressed pixel data: the data is damaged, or GDCM cannot "
        "decode it",
        Said()));
  }
  Stop(0);
  return absl::InternalError(absl::StrCat(
      path, ": the DICOM decoder answered outside its protocol (", what, ") and was stopped"));
}

absl::Status DicomDecoder::Decode(const std::string& path, const std::string& bytes, int rows,
                                  int columns, int bits, int frames, double seconds,
                                  std::vector<char>* out) {
  if (stopped_) {
    return absl::FailedPreconditionError(
        absl::StrCat(path, ": the DICOM decoder stopped on an earlier file"));
  }
  dd::Request request;
  request.rows = static_cast<uint32_t>(std::max(rows, 0));
  request.columns = static_cast<uint32_t>(std::max(columns, 0));
  request.bits = static_cast<uint32_t>(std::max(bits, 0));
  request.frames = static_cast<uint32_t>(std::max(frames, 0));
  request.length = bytes.size();
  if (!request.Valid()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": ", frames, " frames of ", columns, "x", rows, " ", bits,
                     "-bit pixels, more than the DICOM decoder takes"));
  }
  const double allowed = seconds + static_cast<double>(request.DecodedBytes()) / kBytesPerSecond;
  const int64_t deadline = After(allowed);
  char head[dd::kRequestBytes];
  dd::MakeRequest(request, head);
  char reply_head[dd::kReplyBytes];
  Io io = Pump(head, sizeof(head), nullptr, 0, deadline);
  if (io == Io::kDone) io = Pump(bytes.data(), bytes.size(), nullptr, 0, deadline);
  if (io == Io::kDone) io = Pump(nullptr, 0, reply_head, sizeof(reply_head), deadline);
  if (io != Io::kDone) return Failed(path, io, allowed, "");
  const std::optional<dd::Reply> reply = dd::ReadReply(reply_head);
  if (!reply) return Failed(path, Io::kDone, allowed, "a reply without its mark");
  if (reply->status == dd::kDecoded && reply->length == request.DecodedBytes()) {
    out->resize(reply->length);
    io = Pump(nullptr, 0, out->data(), out->size(), deadline);
    if (io != Io::kDone) return Failed(path, io, allowed, "");
    return absl::OkStatus();
  }
  if (reply->status == dd::kRefused && reply->length <= dd::kMaxReason) {
    std::string reason(reply->length, '\0');
    io = Pump(nullptr, 0, reason.data(), reason.size(), deadline);
    if (io != Io::kDone) return Failed(path, io, allowed, "");
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", Printable(reason, 1000)));
  }
  return Failed(path, Io::kDone, allowed,
                absl::StrCat("a reply of status ", reply->status, " and ", reply->length,
                             " bytes, for ", request.DecodedBytes(), " bytes of pixels"));
}

}  // namespace transtick
