// The workbench's page (src/serve/page/) and Debian's dygraphs, embedded into the binary at build
// time (src/serve/embed_files.cmake): the page works offline, and the server reads no file.
#pragma once

#include <string_view>
#include <vector>

namespace valvediag::serve {

struct StaticFile {
  std::string_view path;          // the URL path, e.g. "/" or "/static/app.js"
  std::string_view content_type;  // e.g. "text/javascript; charset=utf-8"
  std::string_view body;
};

const std::vector<StaticFile>& static_files();

}  // namespace valvediag::serve
