// transtick-dicom-decode: decodes compressed DICOM pixel data with GDCM in
// a process of its own, for the DICOM reader (dicom.cc, dicom_decoder.h),
// so that a codec that crashes, hangs or leaks on a damaged file takes only
// this process down. It reads requests on standard input and answers on
// standard output (docs/formats.md, "DICOM decoder process"); not a
// program for people to run.
#include <fcntl.h>
#include <linux/audit.h>
#include <linux/filter.h>
#include <linux/seccomp.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <string>
#include <string_view>
#include <vector>

#include "dicom_decoder_protocol.h"
#include "dicom_module.h"

// dicom_gdcm.cc, compiled into this program.
extern "C" void transtick_dicom_read_pixels(std::string* bytes, int rows, int columns, int bits,
                                            int frames, transtick::DicomPixels* out);

namespace {

namespace dd = transtick::dicom_decoder;

#if defined(__SANITIZE_ADDRESS__)
constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr bool kAddressSanitizer = true;
#else
constexpr bool kAddressSanitizer = false;
#endif
#else
constexpr bool kAddressSanitizer = false;
#endif

// Reads exactly n bytes; false at the end of the input or on an error
// (`*clean` says whether the input ended before the first byte).
bool ReadAll(char* p, size_t n, bool* clean) {
  *clean = false;
  size_t got = 0;
  while (got < n) {
    const ssize_t r = ::read(0, p + got, n - got);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) {
      *clean = r == 0 && got == 0;
      return false;
    }
    got += static_cast<size_t>(r);
  }
  return true;
}

bool WriteAll(const char* p, size_t n) {
  while (n > 0) {
    const ssize_t w = ::write(1, p, n);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    p += w;
    n -= static_cast<size_t>(w);
  }
  return true;
}

// Confines this process, for good, to the system calls a decode needs:
// reading and writing its descriptors, memory, time, and ending (abort
// too). Anything else (opening a file, a socket, running a program,
// starting a process) fails with EPERM, so code that a hostile file
// takes over can do no more than answer with wrong pixels. A seccomp
// filter; false when the kernel refuses it.
// On a processor other than these two it refuses (the decoder then
// refuses to run): the filter checks the system call numbers of one.
#if defined(__x86_64__) || defined(__aarch64__)
bool Confine() {
#if defined(__x86_64__)
  constexpr uint32_t kArch = AUDIT_ARCH_X86_64;
#else
  constexpr uint32_t kArch = AUDIT_ARCH_AARCH64;
#endif
  const std::vector<uint32_t> allowed = {SYS_read,         SYS_write,          SYS_readv,
                                         SYS_writev,       SYS_close,          SYS_lseek,
                                         SYS_fstat,        SYS_newfstatat,     SYS_brk,
                                         SYS_mmap,         SYS_munmap,         SYS_mremap,
                                         SYS_madvise,      SYS_mprotect,       SYS_futex,
                                         SYS_sched_yield,  SYS_getrandom,      SYS_clock_gettime,
                                         SYS_gettimeofday, SYS_nanosleep,      SYS_clock_nanosleep,
                                         SYS_getpid,       SYS_gettid,         SYS_tgkill,
                                         SYS_rt_sigaction, SYS_rt_sigprocmask, SYS_rt_sigreturn,
                                         SYS_exit,         SYS_exit_group};
  std::vector<sock_filter> program = {
      BPF_STMT(BPF_LD | BPF_W | BPF_ABS, offsetof(seccomp_data, arch)),
      BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, kArch, 1, 0),
      BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_KILL_PROCESS),
      BPF_STMT(BPF_LD | BPF_W | BPF_ABS, offsetof(seccomp_data, nr))};
  for (uint32_t nr : allowed) {
    program.push_back(BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, nr, 0, 1));
    program.push_back(BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ALLOW));
  }
  program.push_back(BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ERRNO | (EPERM & SECCOMP_RET_DATA)));
  const sock_fprog fprog = {static_cast<unsigned short>(program.size()), program.data()};
  return ::prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) == 0 &&
         ::prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, &fprog) == 0;
}
#else
bool Confine() { return false; }
#endif

// What opening `path` and making a socket do: "ok" or the error.
void Probe(const char* when, const char* path) {
  const int fd = ::open(path, O_RDONLY | O_CLOEXEC);
  std::printf("%s: open %s, ", when, fd >= 0 ? "ok" : std::strerror(errno));
  if (fd >= 0) ::close(fd);
  const int sock = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  std::printf("socket %s\n", sock >= 0 ? "ok" : std::strerror(errno));
  std::fflush(stdout);
  if (sock >= 0) ::close(sock);
}

bool Answer(uint32_t status, std::string_view body) {
  char head[dd::kReplyBytes];
  dd::MakeReply({status, body.size()}, head);
  return WriteAll(head, sizeof(head)) && WriteAll(body.data(), body.size());
}

int Fail(const char* message) {
  std::fprintf(stderr, "transtick-dicom-decode: %s\n", message);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  uint64_t max_memory = 0;
  const char* probe = nullptr;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg.substr(0, 13) == "--max-memory=") {
      max_memory = std::strtoull(argv[i] + 13, nullptr, 10);
    } else if (arg.substr(0, 16) == "--probe-sandbox=") {
      probe = argv[i] + 16;
    } else {
      return Fail(
          "usage: transtick-dicom-decode [--max-memory=BYTES] [--probe-sandbox=FILE] (run by "
          "transtick's DICOM reader)");
    }
  }
  // --probe-sandbox: what the confinement refuses, for its test. Opens FILE
  // and a socket before and after it, prints what each did, and exits.
  if (probe != nullptr) {
    Probe("before", probe);
    if (!Confine()) return Fail("cannot confine itself (seccomp)");
    Probe("after", probe);
    return 0;
  }
  // A crash leaves no core file of a hostile file's pixels behind.
  const rlimit no_core = {0, 0};
  ::setrlimit(RLIMIT_CORE, &no_core);
  if (max_memory > 0 && !kAddressSanitizer) {
    const rlimit memory = {max_memory, max_memory};
    if (::setrlimit(RLIMIT_AS, &memory) != 0) return Fail("cannot limit its address space");
  }
  if (!Confine()) return Fail("cannot confine itself (seccomp)");
  char hello[dd::kHelloBytes];
  dd::MakeHello(hello);
  if (!WriteAll(hello, sizeof(hello))) return 1;
  for (;;) {
    char head[dd::kRequestBytes];
    bool clean = false;
    if (!ReadAll(head, sizeof(head), &clean)) return clean ? 0 : Fail("request cut short");
    const std::optional<dd::Request> request = dd::ReadRequest(head);
    if (!request || !request->Valid()) return Fail("not a request it can take");
    std::string bytes;
    try {
      bytes.resize(request->length);
    } catch (const std::bad_alloc&) {
      return Fail("out of memory for the file's bytes");
    }
    if (!ReadAll(bytes.data(), bytes.size(), &clean)) return Fail("request cut short");
    transtick::DicomPixels pixels;
    transtick_dicom_read_pixels(&bytes, static_cast<int>(request->rows),
                                static_cast<int>(request->columns), static_cast<int>(request->bits),
                                static_cast<int>(request->frames), &pixels);
    bool sent;
    if (!pixels.error.empty()) {
      sent = Answer(dd::kRefused, std::string_view(pixels.error).substr(0, dd::kMaxReason));
    } else if (pixels.bytes.size() != request->DecodedBytes()) {
      sent = Answer(dd::kRefused, "GDCM decoded a different number of pixels");
    } else {
      sent = Answer(dd::kDecoded, std::string_view(pixels.bytes.data(), pixels.bytes.size()));
    }
    if (!sent) return 1;
  }
}
