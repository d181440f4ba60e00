// The socket side of `ltmapper view`: cpp-httplib hands every request to Viewer::Handle.
#include "ltmapper/view/view.hpp"

#include <httplib.h>

#include <sys/socket.h>

#include <memory>

namespace ltm::view {
namespace {

// httplib's request -> ours; a repeated query parameter is ambiguous and refused.
bool ToRequest(const httplib::Request& in, Request& out) {
  out.method = in.method;
  out.path = in.path;
  for (const auto& [k, v] : in.params)
    if (!out.query.emplace(k, v).second) return false;
  return true;
}

void Reply(const Viewer& viewer, const httplib::Request& in, httplib::Response& out) {
  Request req;
  Response res;
  if (ToRequest(in, req)) res = viewer.Handle(req);
  else res = {400, "text/plain; charset=utf-8", "repeated query parameter\n"};
  out.status = res.status;
  out.set_header("Cache-Control", "no-store");
  // Sent with its length from a provider: httplib then sends it as is. set_content would let it
  // compress text with brotli at its highest quality (3.3 s for three.js's 1.3 MB on one core);
  // on this machine's own address the bytes cost nothing.
  auto body = std::make_shared<const std::string>(std::move(res.body));
  out.set_content_provider(body->size(), res.content_type.c_str(),
                           [body](std::size_t offset, std::size_t length, httplib::DataSink& sink) {
                             return sink.write(body->data() + offset, length);
                           });
}

}  // namespace

void Serve(const Viewer& viewer, const std::string& host, int port, const std::function<void(int)>& on_ready) {
  httplib::Server server;
  // httplib's default sets SO_REUSEPORT: a second viewer on the same port would then share it,
  // each request going to either. SO_REUSEADDR alone restarts at once after a stop, and a port
  // in use is an error.
  server.set_socket_options([](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  });
  const auto handler = [&viewer](const httplib::Request& in, httplib::Response& out) { Reply(viewer, in, out); };
  server.Get(".*", handler);
  server.Post(".*", handler);
  server.Put(".*", handler);
  server.Delete(".*", handler);
  server.Patch(".*", handler);
  server.Options(".*", handler);
  const int bound = port == 0 ? server.bind_to_any_port(host) : (server.bind_to_port(host, port) ? port : -1);
  if (bound <= 0) throw Error("view: cannot listen on " + host + ":" + std::to_string(port) + " (in use, or not an address of this machine)");
  if (on_ready) on_ready(bound);
  if (!server.listen_after_bind()) throw Error("view: the server on " + host + ":" + std::to_string(bound) + " stopped");
}

}  // namespace ltm::view
