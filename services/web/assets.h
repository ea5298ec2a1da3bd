// The viewer page's files, compiled into the gateway from
// services/web/static (cmake/embed.cmake).
#ifndef TRANSTICK_SERVICES_WEB_ASSETS_H_
#define TRANSTICK_SERVICES_WEB_ASSETS_H_

#include <string_view>
#include <vector>

namespace transtick {

struct WebAsset {
  std::string_view path;          // "/index.html"
  std::string_view bytes;
};

const std::vector<WebAsset>& WebAssets();

}  // namespace transtick

#endif  // TRANSTICK_SERVICES_WEB_ASSETS_H_
