#include "security.h"

#include <grpcpp/security/auth_context.h>
#include <grpcpp/security/auth_metadata_processor.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "rpc_status.h"

namespace transtick {
namespace {

// The client a call's "authorization: Bearer TOKEN" names; OK with no
// client when the call has no such header. One header at most.
absl::StatusOr<std::optional<Client>> BearerClient(
    const std::multimap<grpc::string_ref, grpc::string_ref>& metadata, const TokenTable& tokens) {
  auto [first, last] = metadata.equal_range("authorization");
  if (first == last) return std::optional<Client>();
  if (std::next(first) != last) {
    return absl::UnauthenticatedError("a call may carry one authorization header");
  }
  absl::string_view value(first->second.data(), first->second.size());
  if (!absl::ConsumePrefix(&value, "Bearer ")) {
    return absl::UnauthenticatedError("the authorization header is not a bearer token");
  }
  std::optional<Client> client = tokens.Find(value);
  if (!client) return absl::UnauthenticatedError("the bearer token is not one this root knows");
  return client;
}

// Written once by SetSecurity before any thread or channel exists, then
// only read: no lock.
Security* security = new Security();

bool ValidName(absl::string_view name) {
  if (name.empty() || name.size() > 64) return false;
  for (char c : name) {
    if (!absl::ascii_isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '_' && c != '-')
      return false;
  }
  return true;
}

bool SameBytes(absl::string_view a, absl::string_view b) {
  if (a.size() != b.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < a.size(); ++i) diff |= static_cast<unsigned char>(a[i] ^ b[i]);
  return diff == 0;
}

absl::StatusOr<std::string> ReadSmallFile(const std::string& path, const std::string& what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(what, ": cannot read ", path));
  std::ostringstream text;
  text << in.rdbuf();
  std::string s = text.str();
  if (s.size() > (1 << 20)) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": ", path, " is larger than 1 MB"));
  }
  return s;
}

std::string Env(const char* name) {
  const char* v = std::getenv(name);
  return v ? v : "";
}

std::string FlagOrEnv(const Flags& flags, const std::string& flag, const char* env) {
  return flags.Has(flag) ? flags.Get(flag) : Env(env);
}

// The role a peer's verified certificate names, if any.
std::optional<Role> RoleOf(const grpc::AuthContext& ctx) {
  if (!ctx.IsPeerAuthenticated()) return std::nullopt;
  for (const auto& cn : ctx.FindPropertyValues("x509_common_name")) {
    const absl::string_view name(cn.data(), cn.size());
    for (Role r : {Role::kRoot, Role::kWorker, Role::kDisplay}) {
      if (name == RoleName(r)) return r;
    }
  }
  return std::nullopt;
}

// The root's check of every call: a known bearer token names the client;
// a call without one must come from a daemon of the cluster (its
// certificate is checked again by the method). Runs on gRPC's transport
// thread: a map lookup, nothing that blocks.
class TokenCheck : public grpc::AuthMetadataProcessor {
 public:
  explicit TokenCheck(std::shared_ptr<const TokenTable> tokens) : tokens_(std::move(tokens)) {}
  bool IsBlocking() const override { return false; }

  // The header stays on the call: the method finds the client from it
  // again (CallingClient). Properties added to `context` here would not do:
  // they outlive the call on the connection's context.
  grpc::Status Process(const InputMetadata& metadata, grpc::AuthContext* context,
                       OutputMetadata*, OutputMetadata*) override {
    auto client = BearerClient(metadata, *tokens_);
    if (!client.ok()) return ToGrpc(client.status());
    if (*client || RoleOf(*context)) return grpc::Status::OK;
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED,
                        "the root needs a bearer token: give the transtick command "
                        "--token-file FILE (docs/security.md)");
  }

 private:
  const std::shared_ptr<const TokenTable> tokens_;
};

}  // namespace

absl::string_view RoleName(Role role) {
  switch (role) {
    case Role::kRoot:
      return "transtick-root";
    case Role::kWorker:
      return "transtick-worker";
    case Role::kDisplay:
      return "transtick-display";
  }
  return "";
}

absl::StatusOr<TokenTable> TokenTable::Parse(absl::string_view text, const std::string& source) {
  TokenTable table;
  std::set<std::string> names;
  int line_no = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_no;
    if (size_t hash = line.find('#'); hash != absl::string_view::npos) line = line.substr(0, hash);
    std::vector<absl::string_view> fields =
        absl::StrSplit(line, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (fields.empty()) continue;
    const std::string where = absl::StrCat(source, ":", line_no);
    if (fields.size() < 2 || fields.size() > 3 || (fields.size() == 3 && fields[2] != "admin")) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": expected NAME TOKEN [admin]"));
    }
    if (!ValidName(fields[0])) {
      return absl::InvalidArgumentError(absl::StrCat(
          where, ": a client name is 1-64 letters, digits, '.', '_' or '-'"));
    }
    if (fields[1].size() < 16) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": the token of '", fields[0], "' is shorter than 16 characters"));
    }
    if (!names.insert(std::string(fields[0])).second) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": client '", fields[0], "' is listed twice"));
    }
    Client c{std::string(fields[0]), fields.size() == 3};
    if (!table.clients_.emplace(std::string(fields[1]), std::move(c)).second) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": a token is listed twice"));
    }
  }
  if (table.clients_.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": no clients listed"));
  }
  return table;
}

absl::StatusOr<TokenTable> TokenTable::Load(const std::string& path) {
  auto text = ReadSmallFile(path, "--tokens");
  if (!text.ok()) return text.status();
  return Parse(*text, path);
}

std::optional<Client> TokenTable::Find(absl::string_view token) const {
  // Every entry is compared, each in constant time: how long this takes
  // says nothing about which token is closest.
  std::optional<Client> found;
  for (const auto& [t, c] : clients_) {
    if (SameBytes(t, token)) found = c;
  }
  return found;
}

std::set<std::string> WithSecurityFlags(std::set<std::string> known) {
  known.insert({"tls-ca", "tls-cert", "tls-key", "tokens", "token-file"});
  return known;
}

std::vector<FlagDoc> ClientSecurityFlagDocs() {
  return {
      {"tls-ca", "FILE", "the cluster's CA certificate: TLS on ($TRANSTICK_TLS_CA)"},
      {"token-file", "FILE", "this client's bearer token ($TRANSTICK_TOKEN_FILE)"},
      {"tls-cert", "FILE", "a client certificate, with --tls-key ($TRANSTICK_TLS_CERT)"},
      {"tls-key", "FILE", "its key ($TRANSTICK_TLS_KEY)"},
      {"insecure", "", "allow plaintext to a non-loopback address ($TRANSTICK_INSECURE)"},
  };
}

std::set<std::string> WithSecuritySwitches(std::set<std::string> switches) {
  switches.insert("insecure");
  return switches;
}

absl::StatusOr<Security> SecurityFromFlags(const Flags& flags, bool daemon) {
  Security s;
  s.insecure = flags.Has("insecure") || !Env("TRANSTICK_INSECURE").empty();
  const std::string ca = FlagOrEnv(flags, "tls-ca", "TRANSTICK_TLS_CA");
  const std::string cert = FlagOrEnv(flags, "tls-cert", "TRANSTICK_TLS_CERT");
  const std::string key = FlagOrEnv(flags, "tls-key", "TRANSTICK_TLS_KEY");
  const std::string tokens = FlagOrEnv(flags, "tokens", "TRANSTICK_TOKENS");
  const std::string token_file = FlagOrEnv(flags, "token-file", "TRANSTICK_TOKEN_FILE");
  if (ca.empty() && (!cert.empty() || !key.empty() || !tokens.empty() || !token_file.empty())) {
    return absl::InvalidArgumentError(
        "--tls-cert, --tls-key, --tokens and --token-file need --tls-ca: tokens and "
        "certificates are only sent over TLS");
  }
  if (cert.empty() != key.empty()) {
    return absl::InvalidArgumentError("--tls-cert and --tls-key go together");
  }
  if (daemon && !ca.empty() && cert.empty()) {
    return absl::InvalidArgumentError(
        "a daemon with --tls-ca needs its certificate and key too (--tls-cert, --tls-key)");
  }
  for (auto [path, field, flag] : {std::tuple{&ca, &s.ca, "--tls-ca"},
                                   std::tuple{&cert, &s.cert, "--tls-cert"},
                                   std::tuple{&key, &s.key, "--tls-key"}}) {
    if (path->empty()) continue;
    auto text = ReadSmallFile(*path, flag);
    if (!text.ok()) return text.status();
    if (!absl::StrContains(*text, "-----BEGIN ")) {
      return absl::InvalidArgumentError(absl::StrCat(flag, ": ", *path, " is not PEM"));
    }
    *field = *std::move(text);
  }
  if (!tokens.empty()) {
    auto table = TokenTable::Load(tokens);
    if (!table.ok()) return table.status();
    s.tokens = std::make_shared<const TokenTable>(*std::move(table));
  }
  if (!token_file.empty()) {
    auto text = ReadSmallFile(token_file, "--token-file");
    if (!text.ok()) return text.status();
    s.token = std::string(absl::StripAsciiWhitespace(*text));
    if (s.token.size() < 16 || s.token.find_first_of(" \t\r\n") != std::string::npos) {
      return absl::InvalidArgumentError(
          absl::StrCat("--token-file: ", token_file, " must hold one token of 16 or more "
                       "characters"));
    }
  }
  return s;
}

void SetSecurity(Security s) { *security = std::move(s); }

const Security& CurrentSecurity() { return *security; }

std::shared_ptr<grpc::ChannelCredentials> ChannelCredentialsFor(Role role,
                                                                grpc::ChannelArguments* args) {
  const Security& s = CurrentSecurity();
  if (!s.tls()) return grpc::InsecureChannelCredentials();
  grpc::SslCredentialsOptions o;
  o.pem_root_certs = s.ca;
  o.pem_private_key = s.key;
  o.pem_cert_chain = s.cert;
  // The peer's certificate must name the role dialled, whatever its address.
  args->SetSslTargetNameOverride(std::string(RoleName(role)));
  auto creds = grpc::SslCredentials(o);
  if (role == Role::kRoot && !s.token.empty()) {
    creds = grpc::CompositeChannelCredentials(creds, grpc::AccessTokenCredentials(s.token));
  }
  return creds;
}

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(
    Role self, const std::string& address) {
  const Security& s = CurrentSecurity();
  if (!s.tls()) {
    if (!s.insecure && !IsLoopback(address)) {
      return absl::FailedPreconditionError(absl::StrCat(
          "refusing to serve plaintext on ", address,
          ": give --tls-ca, --tls-cert and --tls-key (docs/security.md), listen on a loopback "
          "address, or pass --insecure"));
    }
    return grpc::InsecureServerCredentials();
  }
  if (self == Role::kRoot && !s.tokens) {
    return absl::FailedPreconditionError(
        "the root serves TLS but has no --tokens FILE: its clients could not be told apart");
  }
  grpc::SslServerCredentialsOptions o(
      self == Role::kRoot ? GRPC_SSL_REQUEST_CLIENT_CERTIFICATE_AND_VERIFY
                          : GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  o.pem_root_certs = s.ca;
  o.pem_key_cert_pairs.push_back({s.key, s.cert});
  auto creds = grpc::SslServerCredentials(o);
  if (self == Role::kRoot) creds->SetAuthMetadataProcessor(std::make_shared<TokenCheck>(s.tokens));
  return creds;
}

grpc::Status RequireRole(const grpc::ServerContextBase& ctx, absl::string_view method,
                         std::initializer_list<Role> roles) {
  if (!CurrentSecurity().tls()) return grpc::Status::OK;
  std::optional<Role> role;
  if (auto auth = ctx.auth_context()) role = RoleOf(*auth);
  for (Role r : roles) {
    if (role == r) return grpc::Status::OK;
  }
  std::string allowed;
  for (Role r : roles) absl::StrAppend(&allowed, allowed.empty() ? "" : " or ", RoleName(r));
  return grpc::Status(
      grpc::StatusCode::PERMISSION_DENIED,
      absl::StrCat(method, " is for ", allowed, "; the caller's certificate is ",
                   role ? absl::StrCat("of ", RoleName(*role)) : std::string("not the cluster's")));
}

absl::StatusOr<Client> CallingClient(const grpc::ServerContextBase& ctx,
                                     const std::string& fallback) {
  const std::shared_ptr<const TokenTable> tokens = CurrentSecurity().tokens;
  if (!tokens) return Client{fallback, /*admin=*/true};
  auto client = BearerClient(ctx.client_metadata(), *tokens);
  if (!client.ok()) return client.status();
  if (!*client) {
    return absl::UnauthenticatedError("this call needs a client's bearer token (--token-file)");
  }
  return **client;
}

std::string Printable(absl::string_view text) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  out.reserve(text.size());
  auto hex = [&out](unsigned char c) {
    out += "\\x";
    out += kHex[c >> 4];
    out += kHex[c & 15];
  };
  for (size_t i = 0; i < text.size(); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == '\\') {
      out += "\\\\";
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (c == '\t') {
      out += "\\t";
    } else if (c < 0x20 || c == 0x7f) {
      hex(c);
    } else if (c == 0xc2 && i + 1 < text.size() &&
               (static_cast<unsigned char>(text[i + 1]) & 0xe0) == 0x80) {
      // U+0080..U+009F, the C1 controls (CSI among them) in UTF-8.
      hex(c);
      hex(static_cast<unsigned char>(text[++i]));
    } else {
      out += text[i];
    }
  }
  return out;
}

bool IsLoopback(const std::string& address) {
  absl::string_view host = address;
  if (const size_t colon = host.rfind(':'); colon != absl::string_view::npos) {
    host = host.substr(0, colon);
  }
  if (absl::ConsumePrefix(&host, "[")) absl::ConsumeSuffix(&host, "]");
  return host == "localhost" || host == "::1" || absl::StartsWith(host, "127.");
}

}  // namespace transtick
