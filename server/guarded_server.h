// A cpp-httplib server whose connections have a deadline per request, not only an idle timeout.
//
// cpp-httplib (0.11, Debian) times out a read or a write that waits longer than its timeout, but a client
// that trickles one byte just inside that timeout (the "slowloris" attack on the head, "R.U.D.Y." on the
// body, a slow reader on the response) keeps a connection thread for as long as it likes: with the thread
// pool taken, the server answers nobody. GuardedServer runs each connection's keep-alive loop itself (the
// library's request handling stays the library's, `Server::process_request`) over a stream that holds
// every request to
//
//     elapsed since the request's first byte was awaited  <=  head_seconds + bytes moved / min_rate
//
// (bytes moved: request and response bytes together), and still to `idle_seconds` for any single wait.
// A request that falls behind is cut: its connection is closed. A well-behaved client on a slow link
// loses nothing: a download at min_rate bytes a second or faster never falls behind.
//
// Connections are served by a pool of `threads`; a kept-alive connection holds its thread between
// requests, so while accepted connections wait for a thread, the connections being served are closed
// after their current request ("Connection: close") instead of kept alive: a few hundred clients polling
// on kept-alive connections take turns instead of starving everyone beyond the pool.
#pragma once

#include <atomic>
#include <cstddef>

#include <httplib.h>

namespace lodstream::serve {

struct ConnectionLimits {
  int idle_seconds = 10;          // longest single wait for the client to send or receive
  int head_seconds = 30;          // the request line and headers (plus any slack) must arrive within this
  size_t min_rate = 1024;         // bytes a second a request must average after that
  int keep_alive_seconds = 5;     // wait for the next request on a kept-alive connection
  int keep_alive_requests = 100;  // requests on one connection
  size_t threads = 64;            // connections served at once
};

class GuardedServer : public httplib::Server {
 public:
  explicit GuardedServer(const ConnectionLimits& limits);

  // After bind_to_port: lets `backlog` connections wait to be accepted (cpp-httplib 0.11 listens with 5,
  // so a burst of clients beyond that has its SYNs dropped and retried a second or more later).
  void widen_backlog(int backlog);

 private:
  // Overrides the library's connection loop (a private virtual of httplib::Server, called for each
  // accepted socket on a pool thread); closes the socket.
  bool process_and_close_socket(socket_t sock) override;

  ConnectionLimits limits_;
  std::atomic<size_t> waiting_{0};  // accepted connections waiting for a thread
};

}  // namespace lodstream::serve
