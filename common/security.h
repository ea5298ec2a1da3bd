// Who may talk to whom (docs/security.md). Every daemon serves TLS and
// proves who it is with a certificate of the cluster's CA whose common name
// (and DNS name) is its role: "transtick-root", "transtick-worker" or
// "transtick-display". Daemons ask each other for those certificates
// (mutual TLS), and a channel to a peer checks that the peer's certificate
// names the role it dialled, so a worker sends rays only to a worker and
// deposits only to a display. Clients of the root's API need no
// certificate: they send a bearer token, which the root maps to a client
// name (job ownership) and maybe admin rights.
//
// Without TLS configured, a daemon serves plaintext only on a loopback
// address (the embedded cluster, tests), or anywhere with an explicit
// --insecure, and then nobody is authenticated. The process's settings are
// set once at startup, before any channel or server is made.
#ifndef TRANSTICK_COMMON_SECURITY_H_
#define TRANSTICK_COMMON_SECURITY_H_

#include <grpcpp/security/credentials.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server_context.h>
#include <grpcpp/support/channel_arguments.h>

#include <initializer_list>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "absl/strings/string_view.h"

#include "absl/status/statusor.h"
#include "flags.h"

namespace transtick {

enum class Role { kRoot, kWorker, kDisplay };
// The common name of a role's certificate: "transtick-worker".
absl::string_view RoleName(Role role);

// A client of the root, as its bearer token names it.
struct Client {
  std::string name;
  bool admin = false;
};

// The root's table of clients by token, read from a file of lines
// "NAME TOKEN [admin]" ('#' starts a comment). Tokens are at least 16
// characters; names are letters, digits and "._-".
class TokenTable {
 public:
  static absl::StatusOr<TokenTable> Parse(absl::string_view text, const std::string& source);
  static absl::StatusOr<TokenTable> Load(const std::string& path);
  // The client holding `token`, compared in time independent of where the
  // tokens differ.
  std::optional<Client> Find(absl::string_view token) const;
  size_t size() const { return clients_.size(); }

 private:
  std::map<std::string, Client> clients_;  // by token
};

struct Security {
  // PEM. With a CA, TLS is on: servers serve it, channels dial with it.
  std::string ca, cert, key;
  // A client's bearer token, sent on every call to the root ("" none).
  std::string token;
  // The root's clients; null when clients are not authenticated.
  std::shared_ptr<const TokenTable> tokens;
  // Plaintext is allowed on addresses other than loopback.
  bool insecure = false;

  bool tls() const { return !ca.empty(); }
};

// Reads --tls-ca, --tls-cert, --tls-key (and $TRANSTICK_TLS_CA, ...),
// --insecure, and for the root --tokens FILE, for a client --token-file
// FILE ($TRANSTICK_TOKEN_FILE). A daemon (`daemon`) needs a certificate and
// key with the CA; a client needs only the CA. Errors name the flag and
// the file.
absl::StatusOr<Security> SecurityFromFlags(const Flags& flags, bool daemon);
// `known` with the flags SecurityFromFlags reads, for Flags::Parse; the
// switch --insecure with WithSecuritySwitches.
std::set<std::string> WithSecurityFlags(std::set<std::string> known);
std::set<std::string> WithSecuritySwitches(std::set<std::string> switches);
// The flags a client command reads, documented for its --help.
std::vector<FlagDoc> ClientSecurityFlagDocs();
// Usage text for them.
inline constexpr char kSecurityUsage[] =
    "[--tls-ca FILE --tls-cert FILE --tls-key FILE] [--insecure]";

// Sets the process's security. Call once, at startup, before any thread,
// channel or server exists (it is then read without a lock).
void SetSecurity(Security security);
const Security& CurrentSecurity();

// Credentials, and the arguments that go with them, for a channel to a
// peer of `role` (with TLS, its certificate must name that role).
std::shared_ptr<grpc::ChannelCredentials> ChannelCredentialsFor(Role role,
                                                                grpc::ChannelArguments* args);
// Credentials for a server of `self` on `address`: TLS with client
// certificates required (workers, display) or verified when given (the
// root, whose clients send tokens instead). Plaintext on a non-loopback
// address without `insecure` is an error naming the address.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ServerCredentialsFor(
    Role self, const std::string& address);

// OK when security is off or the caller's certificate is of one of
// `roles`; else PERMISSION_DENIED naming the method and who may call it.
grpc::Status RequireRole(const grpc::ServerContextBase& ctx, absl::string_view method,
                         std::initializer_list<Role> roles);
// The client calling: from its token when the root has tokens, else (no
// authentication) `fallback` with admin rights. UNAUTHENTICATED without a
// known token.
absl::StatusOr<Client> CallingClient(const grpc::ServerContextBase& ctx,
                                     const std::string& fallback);

// `text` (a client's string: a job name, a path, an error quoting them) as a
// log line or a terminal may show it: control characters and DEL become
// \n, \r, \t or \xNN, and a backslash \\; everything else, UTF-8 included,
// stays as it is. No client string can then forge a line or move a cursor.
std::string Printable(absl::string_view text);

// Whether `address`'s host is a loopback address (127.0.0.0/8, ::1,
// localhost).
bool IsLoopback(const std::string& address);

}  // namespace transtick

#endif  // TRANSTICK_COMMON_SECURITY_H_
