#include "server/console/web_console.h"

#include <filesystem>

#include <httplib.h>
#include <openssl/evp.h>
#include <openssl/sha.h>
#include <spdlog/spdlog.h>

#include "core/common/file_io.h"
#include "core/common/text.h"
#include "server/console/console_views.h"

namespace recog::server {
namespace {

constexpr std::chrono::milliseconds kLiveInterval{1000};
constexpr size_t kLiveSamples = 300;  // five minutes

std::string Authorization(const httplib::Request& request) {
  return request.get_header_value("Authorization");
}

void Send(const HttpReply& reply, httplib::Response* response) {
  response->status = reply.status;
  response->set_header("Cache-Control", "no-store");
  for (const auto& [name, value] : reply.headers) response->set_header(name.c_str(), value);
  response->set_content(reply.body, reply.content_type.c_str());
}

// The content of the page's inline import map, which the policy must allow by its hash.
std::string InlineImportMap(const std::string& index_html) {
  constexpr std::string_view kOpen = "<script type=\"importmap\">", kClose = "</script>";
  const size_t open = index_html.find(kOpen);
  if (open == std::string::npos) return {};
  const size_t begin = open + kOpen.size();
  const size_t end = index_html.find(kClose, begin);
  return end == std::string::npos ? std::string() : index_html.substr(begin, end - begin);
}

// 'sha256-<base64>' of `text`, as Content-Security-Policy names an inline script.
std::string ScriptHash(const std::string& text) {
  unsigned char digest[SHA256_DIGEST_LENGTH];
  SHA256(reinterpret_cast<const unsigned char*>(text.data()), text.size(), digest);
  unsigned char base64[4 * ((SHA256_DIGEST_LENGTH + 2) / 3) + 1];
  EVP_EncodeBlock(base64, digest, SHA256_DIGEST_LENGTH);
  return "'sha256-" + std::string(reinterpret_cast<const char*>(base64)) + "'";
}

// Sent with every answer: scripts, styles and everything else from the console itself (the page's
// import map by its hash), never framed, types never sniffed, no referrer.
HeaderList SecurityHeaders(const std::string& index_html) {
  std::string scripts = "'self'";
  if (const std::string map = InlineImportMap(index_html); !map.empty()) {
    scripts += " " + ScriptHash(map);
  }
  return {{"Content-Security-Policy",
           "default-src 'self'; script-src " + scripts +
               "; img-src 'self' data: blob:; object-src 'none'; base-uri 'none'; "
               "form-action 'self'; frame-ancestors 'none'"},
          {"X-Content-Type-Options", "nosniff"},
          {"X-Frame-Options", "DENY"},
          {"Referrer-Policy", "no-referrer"}};
}

// A file of `files` (GET /static/..., /vendor/...), or 404.
HttpReply StaticFileReply(const StaticFiles& files, const std::string& path) {
  const StaticFiles::File* file = files.Find(path);
  if (file != nullptr) {
    StatusOr<std::string> content = ReadWholeFile(file->path, "console file");
    if (content.ok()) return {200, file->content_type, std::move(content).value()};
  }
  return {404, "text/plain; charset=utf-8", "no such file"};
}

}  // namespace

std::string DefaultConsoleWebRoot() {
  const std::string in_source = RECOG_CONSOLE_WEB_DIR;
  const std::string installed = RECOG_INSTALLED_CONSOLE_WEB_DIR;
  return std::filesystem::exists(in_source) || !std::filesystem::exists(installed) ? in_source
                                                                                   : installed;
}

WebConsole::WebConsole(ServerState* state, std::shared_ptr<grpc::Channel> channel)
    : state_(state),
      gateway_(std::move(channel)),
      live_([state] { return state->metrics.ReadTotals(); }, kLiveInterval, kLiveSamples),
      body_budget_(state->config.console.max_inflight_body_bytes) {}

StatusOr<std::unique_ptr<WebConsole>> WebConsole::Start(ServerState* state,
                                                        std::shared_ptr<grpc::Channel> channel) {
  const ServerConfig& config = state->config;
  const std::string web_root =
      config.console.web_root.empty() ? DefaultConsoleWebRoot() : config.console.web_root;
  const std::string index = web_root + "/index.html";
  StatusOr<std::string> index_html = ReadWholeFile(index, "the console's index.html");
  if (!index_html.ok()) {
    return Status::NotFound("console.web_root '" + web_root + "' has no readable index.html");
  }
  std::unique_ptr<WebConsole> console(new WebConsole(state, std::move(channel)));
  const HttpsFiles https{config.tls.cert, config.tls.key, config.tls.client_ca};
  const HeaderList security = SecurityHeaders(*index_html);
  std::unique_ptr<httplib::Server> http = MakeGuardedHttpServer(
      LimitsOf(config.console), config.tls.cert.empty() ? nullptr : &https, security);
  if (!http->is_valid()) {
    return Status::FailedPrecondition("the console cannot use the TLS files " + config.tls.cert +
                                      " and " + config.tls.key);
  }
  console->gate_.emplace(config.console.hosts, !config.tls.cert.empty(),
                         config.console.max_body_bytes, &state->auth);
  console->files_.AddFolder("/static", web_root);
  console->files_.AddFolder("/vendor/three", config.console.vendor_dir + "/three");
  console->files_.AddFolder("/vendor/chart.js", config.console.vendor_dir + "/chart.js");
  http->set_default_headers(httplib::Headers(security.begin(), security.end()));
  console->AddRoutes(*http);
  RECOG_ASSIGN_OR_RETURN(console->port_,
                         HttpPort::Listen(std::move(http), config.console.listen, "the console"));
  console->url_ = std::string(config.tls.cert.empty() ? "http" : "https") + "://" +
                  console->port_->host() + ":" + std::to_string(console->port_->port()) + "/";
  spdlog::info("console on {} ({} files)", console->url_, console->files_.size());
  return console;
}

void WebConsole::AddRoutes(httplib::Server& http) {
  ServerState& state = *state_;
  // Before routing, before any body is read: the gate's refusals close the connection.
  http.set_pre_routing_handler(
      [this](const httplib::Request& request, httplib::Response& response) {
        std::optional<HttpReply> refusal = gate_->Check(request);
        if (!refusal.has_value()) return httplib::Server::HandlerResponse::Unhandled;
        refusal->headers.emplace_back("Connection", "close");
        Send(*refusal, &response);
        CloseConnectionAfterResponse();
        return httplib::Server::HandlerResponse::Handled;
      });
  http.Get("/", [](const httplib::Request&, httplib::Response& response) {
    response.set_redirect("/static/index.html");
  });
  http.Get(R"(/(static|vendor)/.+)",
           [this](const httplib::Request& request, httplib::Response& response) {
             HttpReply reply = StaticFileReply(files_, request.path);
             // cpp-httplib cuts the answer to a Range (the guard left one at most).
             if (reply.status == 200 && request.ranges.size() == 1) reply.status = 206;
             Send(reply, &response);
           });
  http.Get("/api/whoami", [&state](const httplib::Request& request, httplib::Response& response) {
    Send(WhoAmIView(state, Authorization(request)), &response);
  });
  // The body is read here, once its bytes fit in the gateway's budget (the gate has checked its
  // Content-Length), so that no more than the budget is ever read and decoded at once.
  http.Post(
      R"(/api/rpc/([A-Za-z0-9_.]+/[A-Za-z0-9_]+))",
      [this](const httplib::Request& request, httplib::Response& response,
             const httplib::ContentReader& read) {
        const uint64_t length = request.get_header_value<uint64_t>("Content-Length");
        const std::optional<ByteBudget::Reservation> reserved = body_budget_.Reserve(length);
        if (!reserved.has_value()) {
          HttpReply busy =
              ErrorReply({grpc::StatusCode::UNAVAILABLE,
                          "the console is decoding as many request bodies as it may at once (" +
                              std::to_string(body_budget_.total()) + " bytes); retry later"});
          busy.headers = {{"Retry-After", "1"}, {"Connection", "close"}};
          Send(busy, &response);
          CloseConnectionAfterResponse();  // the body was not read
          return;
        }
        std::string body;
        body.reserve(length);
        const bool whole = read([&](const char* data, size_t size) {
          if (size > length - body.size()) return false;
          body.append(data, size);
          return true;
        });
        if (!whole || body.size() != length) {
          HttpReply cut = ErrorReply(
              {grpc::StatusCode::INVALID_ARGUMENT, "the body did not arrive whole, or in time"});
          cut.headers = {{"Connection", "close"}};
          Send(cut, &response);
          CloseConnectionAfterResponse();
          return;
        }
        Send(gateway_.Call(request.matches[1].str(), body, Authorization(request)), &response);
      });
  http.Get("/api/maps",
           [this, &state](const httplib::Request& request, httplib::Response& response) {
             Send(MapsView(state, gateway_, Authorization(request)), &response);
           });
  http.Get(R"(/api/maps/([^/]+)/loops)",
           [&state](const httplib::Request& request, httplib::Response& response) {
             Send(LoopsView(state, Authorization(request), request.matches[1].str()), &response);
           });
  http.Get(R"(/api/maps/([^/]+)/frames/([^/]+)/thumbnail)",
           [&state](const httplib::Request& request, httplib::Response& response) {
             Send(ThumbnailView(state, Authorization(request), request.matches[1].str(),
                                request.matches[2].str()),
                  &response);
           });
  http.Get(R"(/api/models/([^/]+))",
           [&state](const httplib::Request& request, httplib::Response& response) {
             Send(ModelView(state, Authorization(request), request.matches[1].str()), &response);
           });
  http.Get(R"(/api/models/([^/]+)/points)",
           [&state](const httplib::Request& request, httplib::Response& response) {
             Send(ModelPointsView(state, Authorization(request), request.matches[1].str(),
                                  request.get_param_value("max")),
                  &response);
           });
  http.Get(R"(/api/models/([^/]+)/views/([^/]+)/image)",
           [&state](const httplib::Request& request, httplib::Response& response) {
             Send(ModelImageView(state, Authorization(request), request.matches[1].str(),
                                 request.matches[2].str()),
                  &response);
           });
  http.Get("/api/charts", [&state](const httplib::Request& request, httplib::Response& response) {
    Send(ChartsView(state, Authorization(request)), &response);
  });
  http.Get("/api/live",
           [this, &state](const httplib::Request& request, httplib::Response& response) {
             Send(LiveView(state, live_, Authorization(request)), &response);
           });
  // A handler that throws answers 500; the exception is logged, never sent.
  http.set_exception_handler(
      [](const httplib::Request& request, httplib::Response& response, std::exception_ptr error) {
        std::string what = "unknown exception";
        try {
          std::rethrow_exception(error);
        } catch (const std::exception& e) {
          what = e.what();
        } catch (...) {
        }
        spdlog::error("console: {} {}: {}", request.method, EscapeForLog(request.path),
                      EscapeForLog(what));
        Send(ErrorReply({grpc::StatusCode::INTERNAL, "internal error (the server log has it)"}),
             &response);
      });
  // Refusals of the HTTP layer (no such route, a malformed request) are JSON under /api/, and
  // plain text elsewhere; they never echo the request.
  http.set_error_handler([](const httplib::Request& request, httplib::Response& response) {
    if (!response.body.empty()) return;
    const int status = response.status;
    const grpc::Status refusal =
        status == 404
            ? grpc::Status(grpc::StatusCode::NOT_FOUND, "no such page or call of the console's API")
            : grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                           "the request is malformed (HTTP " + std::to_string(status) + ")");
    if (request.path.starts_with("/api/")) {
      Send(ErrorReply(refusal), &response);
    } else {
      response.set_content(refusal.error_message(), "text/plain; charset=utf-8");
    }
    response.status = status;
  });
}

}  // namespace recog::server
