// SPDX-License-Identifier: Apache-2.0
#pragma once
// The network API's messages: one table (kMessages, protocol.cpp) of every request a client may
// send, its argument schema, who may send it and what it calls. From the table come the parser
// (parse_request: JSON text in, a typed ApiRequest out, or one error), the dispatch of service
// calls (execute: on the service thread) and the reference section of docs/api.md
// (api_reference_markdown; a test compares the committed page). A new service call is one row:
// its name, its arguments, its gate, its doc and a lambda that calls the service and fills the
// result.
//
// JSON is read and written only in protocol.cpp (nlohmann-json: heavy to compile, so kept out
// of every header); the server (server.cpp) moves strings. Units are SI (rad, m, s) throughout.
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "servoarm/kinematics/chain.hpp"
#include "servoarm/kinematics/ik.hpp"
#include "servoarm/rt/controller.hpp"
#include "servoarm/service/arm_service.hpp"
#include "servoarm/service/stream.hpp"

namespace servoarm::api {

/// The protocol version `hello` reports; bumped when a message or field changes meaning.
inline constexpr int kProtocolVersion = 1;

/// Errors of the API itself (beyond CmdError, whose names the service calls answer with).
enum class ApiError : std::uint8_t {
  bad_json,         ///< the message is not a JSON object
  unauthenticated,  ///< no `hello` with a valid token yet (a token file is configured)
  forbidden,        ///< the client's role may not send this (an observer's command)
  not_in_control,   ///< the command moves the arm: `take_control` first
  controlled,       ///< another client holds control (named in the message)
  rate_limited,     ///< more messages per second than api.max_rate_hz: this one was not run
};
const char* to_string(ApiError e);

/// Who may send a message.
enum class Gate : std::uint8_t {
  open,      ///< anyone, before authentication too (hello)
  observer,  ///< any authenticated client (state, events, queries)
  stop,      ///< any authenticated client, whoever holds control (stop, hold, estop): a stop always wins
  operator_, ///< an operator (take_control, release_control)
  control,   ///< the operator holding control (everything that moves or changes the arm)
};
const char* to_string(Gate g);

/// Where a message runs.
enum class Where : std::uint8_t {
  session,  ///< the network thread (hello, subscriptions, control): no service call
  service,  ///< the service thread (the console thread in armfw): an ArmService call
};

enum class ArgType : std::uint8_t { number, integer, boolean, text, numbers };
const char* to_string(ArgType t);

struct ArgSpec {
  const char* name;
  ArgType type;
  bool required;
  double lo, hi;     ///< numbers, integers, each element of numbers; text: length
  const char* doc;
};

/// One argument's value (unset when the message left an optional one out).
struct ArgValue {
  bool present = false;
  double num = 0;           ///< number, integer (exact), boolean (0 / 1)
  std::string text;
  std::vector<double> list;
};

struct ApiRequest;
struct ServiceCall;
struct ResultFields;  ///< the result's fields (JSON, protocol.cpp only)
using Handler = void (*)(ServiceCall& call, ResultFields& out);

struct MessageSpec {
  const char* name;
  std::span<const ArgSpec> args;
  Gate gate;
  Where where;
  const char* call;  ///< what it calls (the docs' column)
  const char* doc;
  Handler handler;   ///< Where::service: runs it; session messages: nullptr (the server handles them)
};
std::span<const MessageSpec> messages();
/// The message named `name`, nullptr when none.
const MessageSpec* find_message(std::string_view name);

/// A parsed request: its id, its message and its arguments in the table's order.
struct ApiRequest {
  std::int64_t id = 0;
  bool has_id = false;
  const MessageSpec* spec = nullptr;
  std::vector<ArgValue> args;
  /// An argument by name (the table's name; nullptr when the message has none of that name).
  const ArgValue* arg(std::string_view name) const;
};

/// Why a message was refused before it ran: the error code's name and one line.
struct ParseError {
  std::string code;     ///< "" when parsed
  std::string message;
};

/// Parse one message (a WebSocket message or a line of the TCP channel). Every refusal names
/// the field: not JSON, not an object, no `cmd`, unknown command, a missing or unknown
/// argument, a wrong type, NaN / inf (not JSON, refused as bad_json: JSON has no NaN), a
/// value out of its range. `id` is taken first, so a refusal answers the message's id.
ParseError parse_request(std::string_view text, ApiRequest& out);

/// What a service call runs with (the service thread).
struct ServiceContext {
  fw::ArmService* svc = nullptr;
  fw::Controller* ctl = nullptr;
  fw::StreamService* stream = nullptr;  ///< streaming targets (nullptr: refused as unsupported)
  const kin::Chain* chain = nullptr;
  kin::IkSolver ik{};
  fw::ConsoleUnits units{};   ///< a native program's units (the console's)
  std::string programs_dir;   ///< programs.dir: `call` and program names ("" none)
};

struct ServiceCall {
  ServiceContext& cx;
  const ApiRequest& rq;
};

/// Run a service message (spec->where == service) and render its result line (no newline).
std::string execute(ServiceContext& cx, const ApiRequest& rq);

/// Result lines the server renders.
std::string ok_line(const ApiRequest& rq, std::string_view fields_json = {});
std::string error_line(bool has_id, std::int64_t id, std::string_view code, std::string_view message);

/// `hello`'s answer: versions, the robot, its joints (names, types, limits), units, the client's
/// role and id, who holds control.
struct HelloInfo {
  std::string robot;
  double rate_hz = 0;
  const char* role = "";
  std::uint64_t client = 0;
  std::uint64_t controller = 0;  ///< 0: nobody
  bool safety_on = false;        ///< a safety envelope is configured
  std::uint32_t safety_checksum = 0;  ///< CRC-32 of the [safety] section (as `safety` on the console shows it)
};
std::string hello_line(const ApiRequest& rq, const HelloInfo& h, const kin::Chain& chain, const kin::JointLimits& lim);

/// One state sample: `{"topic":"state",...}` from the telemetry (RT clock: cycle and t), the
/// tool pose by FK of the measured joints, and the client's dropped count.
/// What a state sample carries from the service (taken on the service thread, the service's
/// one caller): the running program's place, the feed override, the active tool (with its pose
/// in the flange frame: the state's `tcp`) and frame, the digital outputs.
struct ServiceSnapshot {
  fw::ProgramStatus program;
  int feed_pct = 100;
  std::string tool = "tool0", frame = "base";
  kin::Pose tool_pose = kin::Pose::Identity();
  /// The digital outputs ([[output]] order): name and whether it is on (the drives' output words).
  std::vector<std::pair<std::string, bool>> outputs;
  /// The streaming targets' counts since the stream's start (the state's `stream`).
  fw::StreamStats stream;
  /// The safety envelope in force (hello's `safety`): after a confirmed run-time change, its checksum.
  bool safety_on = false;
  std::uint32_t safety_checksum = 0;
};
/// `svc`: the service's part (nullptr: left out).
std::string state_line(const fw::Telemetry& t, double rate_hz, const kin::Chain& chain, std::uint64_t dropped,
                       const ServiceSnapshot* svc = nullptr);
/// One event of the service's stream: `{"topic":"event","seq":N,...,"missed":M}`.
std::string event_line(const fw::ArmEvent& e, std::string_view detail, std::uint64_t missed);
/// `{"topic":"control","holder":N}` (0: nobody).
std::string control_line(std::uint64_t holder);

/// The reference section of docs/api.md (between its BEGIN / END markers), from the table.
std::string api_reference_markdown();
/// "" when `page` holds exactly api_reference_markdown() between its markers, else the diff.
std::string api_reference_mismatch(const std::string& page);

}  // namespace servoarm::api
