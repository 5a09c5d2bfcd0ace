#include "server/console/web_console.h"

#include <filesystem>

#include <httplib.h>
#include <spdlog/spdlog.h>

#include "server/console/console_views.h"

namespace recog::server {
namespace {

constexpr int kHttpThreads = 4;
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

// "host:port" (or "[v6]:port") into its parts; false when malformed.
bool SplitAddress(const std::string& address, std::string* host, int* port) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == address.size()) return false;
  *host = address.substr(0, colon);
  if (host->front() == '[' && host->back() == ']') *host = host->substr(1, host->size() - 2);
  try {
    size_t used = 0;
    *port = std::stoi(address.substr(colon + 1), &used);
    return used == address.size() - colon - 1 && *port >= 0 && *port <= 65535;
  } catch (const std::exception&) {
    return false;
  }
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
      live_([state] { return state->metrics.ReadTotals(); }, kLiveInterval, kLiveSamples) {}

WebConsole::~WebConsole() {
  if (!thread_.joinable()) return;
  // stop() reaches the listening thread only once it listens: until it has stopped, ask again.
  while (!stopped_) {
    http_->stop();
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  thread_.join();
}

StatusOr<std::unique_ptr<WebConsole>> WebConsole::Start(ServerState* state,
                                                        std::shared_ptr<grpc::Channel> channel) {
  const ServerConfig& config = state->config;
  const std::string web_root =
      config.console.web_root.empty() ? DefaultConsoleWebRoot() : config.console.web_root;
  if (!std::filesystem::exists(std::filesystem::path(web_root) / "index.html")) {
    return Status::NotFound("console.web_root '" + web_root + "' has no index.html");
  }
  std::string host;
  int port = 0;
  if (!SplitAddress(config.console.listen, &host, &port)) {
    return Status::InvalidArgument("console.listen '" + config.console.listen +
                                   "' is not host:port");
  }
  std::unique_ptr<WebConsole> console(new WebConsole(state, std::move(channel)));
  if (config.tls.cert.empty()) {
    console->http_ = std::make_unique<httplib::Server>();
  } else {
    console->http_ = std::make_unique<httplib::SSLServer>(
        config.tls.cert.c_str(), config.tls.key.c_str(),
        config.tls.client_ca.empty() ? nullptr : config.tls.client_ca.c_str());
  }
  httplib::Server& http = *console->http_;
  if (!http.is_valid()) {
    return Status::FailedPrecondition("the console cannot use the TLS files " + config.tls.cert +
                                      " and " + config.tls.key);
  }
  http.new_task_queue = [] { return new httplib::ThreadPool(kHttpThreads); };
  // A frame as JSON: its bytes in base64 (4/3) and the rest of the request.
  console->http_payload_limit_ = size_t(config.max_message_bytes) / 3 * 4 + (64 << 10);
  http.set_payload_max_length(console->http_payload_limit_);
  http.set_file_extension_and_mimetype_mapping("js", "text/javascript");
  http.set_file_extension_and_mimetype_mapping("mjs", "text/javascript");
  http.set_mount_point("/static", web_root);
  http.set_mount_point("/vendor/three", config.console.vendor_dir + "/three");
  http.set_mount_point("/vendor/chart.js", config.console.vendor_dir + "/chart.js");
  console->AddRoutes();
  console->port_ = port == 0 ? http.bind_to_any_port(host) : port;
  if (console->port_ <= 0 || (port != 0 && !http.bind_to_port(host, port))) {
    return Status::Unavailable("the console cannot listen on " + config.console.listen +
                               " (address in use, or not an address of this machine)");
  }
  console->thread_ = std::thread([&http, console = console.get()] {
    http.listen_after_bind();
    console->stopped_ = true;
  });
  spdlog::info("console on {}://{}:{}/", config.tls.cert.empty() ? "http" : "https", host,
               console->port_);
  return console;
}

void WebConsole::AddRoutes() {
  httplib::Server& http = *http_;
  ServerState& state = *state_;
  http.Get("/", [](const httplib::Request&, httplib::Response& response) {
    response.set_redirect("/static/index.html");
  });
  http.Get("/api/whoami", [&state](const httplib::Request& request, httplib::Response& response) {
    Send(WhoAmIView(state, Authorization(request)), &response);
  });
  // Only JSON bodies: another site's page can send a form or text/plain to this address without
  // asking, but not application/json (the browser asks first, and the console does not answer
  // CORS), so a console without tokens cannot be driven by a page the operator happens to open.
  http.Post(R"(/api/rpc/([A-Za-z0-9_.]+/[A-Za-z0-9_]+))", [this](const httplib::Request& request,
                                                                 httplib::Response& response) {
    if (!request.get_header_value("Content-Type").starts_with("application/json")) {
      Send(ErrorReply({grpc::StatusCode::INVALID_ARGUMENT,
                       "the body must be JSON sent as Content-Type: application/json"}),
           &response);
      response.status = 415;
      return;
    }
    Send(gateway_.Call(request.matches[1].str(), request.body, Authorization(request)), &response);
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
  // Refusals of the HTTP layer (no such route, a body too large) under /api/ are JSON too.
  http.set_error_handler([max = http_payload_limit_](const httplib::Request& request,
                                                     httplib::Response& response) {
    if (!request.path.starts_with("/api/") || !response.body.empty()) return;
    const int status = response.status;
    // cpp-httplib takes at most 8 KiB of a form: JSON must say that it is JSON.
    const bool form =
        request.get_header_value("Content-Type").starts_with("application/x-www-form-urlencoded");
    const grpc::Status refusal =
        status == 413
            ? grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           form ? std::string("a form body takes at most 8 KiB: send "
                                              "the JSON as Content-Type: "
                                              "application/json")
                                : "the request is larger than the console takes (" +
                                      std::to_string(max) + " bytes)")
            : grpc::Status(grpc::StatusCode::NOT_FOUND, request.method + " " + request.path +
                                                            " is not part of the console's API");
    Send(ErrorReply(refusal), &response);
    response.status = status;
  });
}

}  // namespace recog::server
