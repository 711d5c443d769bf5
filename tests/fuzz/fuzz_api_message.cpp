// SPDX-License-Identifier: Apache-2.0
// libFuzzer target: the network API's message parser (servoarm/api/protocol.hpp). Whatever
// arrives, parse_request returns: either an error code of the documented set with a one-line
// message, or a request whose message is in the table and whose every present argument has
// its type and lies in its range (numbers finite); the result line rendered for it is one
// line of JSON.
#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

#include "servoarm/api/protocol.hpp"

using namespace servoarm;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > 64 * 1024) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  api::ApiRequest rq;
  const api::ParseError e = api::parse_request(text, rq);
  if (!e.code.empty()) {
    if (e.message.empty() || e.message.find('\n') != std::string::npos) __builtin_trap();
    const std::string l = api::error_line(rq.has_id, rq.id, e.code, e.message);
    if (l.find('\n') != std::string::npos) __builtin_trap();
    return 0;
  }
  if (rq.spec == nullptr || api::find_message(rq.spec->name) != rq.spec) __builtin_trap();
  if (rq.args.size() != rq.spec->args.size()) __builtin_trap();
  for (std::size_t i = 0; i < rq.args.size(); ++i) {
    const api::ArgSpec& a = rq.spec->args[i];
    const api::ArgValue& v = rq.args[i];
    if (!v.present) {
      if (a.required) __builtin_trap();
      continue;
    }
    switch (a.type) {
      case api::ArgType::number:
      case api::ArgType::integer:
        if (!std::isfinite(v.num) || v.num < a.lo || v.num > a.hi) __builtin_trap();
        if (a.type == api::ArgType::integer && v.num != std::floor(v.num)) __builtin_trap();
        break;
      case api::ArgType::boolean:
        if (v.num != 0 && v.num != 1) __builtin_trap();
        break;
      case api::ArgType::text:
        if (v.text.size() < a.lo || v.text.size() > a.hi) __builtin_trap();
        break;
      case api::ArgType::numbers:
        for (double d : v.list)
          if (!std::isfinite(d) || d < a.lo || d > a.hi) __builtin_trap();
        break;
    }
  }
  if (api::ok_line(rq).find('\n') != std::string::npos) __builtin_trap();
  return 0;
}
