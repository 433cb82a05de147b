// A tiny HTTP/1.0 GET on loopback, for the tests that scrape fusiond's /metrics.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <string>

namespace fusion::testing {

// GET http://127.0.0.1:port/path (HTTP/1.0: the server closes after the body). The status line
// and headers into *head, the body returned.
inline std::string HttpGet(int port, const std::string& path, std::string* head) {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return "";
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<std::uint16_t>(port));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  timeval timeout{5, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  std::string response;
  if (connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0) {
    const std::string request = "GET " + path + " HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
    if (send(fd, request.data(), request.size(), MSG_NOSIGNAL) ==
        static_cast<ssize_t>(request.size())) {
      char buffer[65536];
      ssize_t n = 0;
      while ((n = recv(fd, buffer, sizeof buffer, 0)) > 0) response.append(buffer, n);
    }
  }
  close(fd);
  const auto end_of_head = response.find("\r\n\r\n");
  if (end_of_head == std::string::npos) {
    *head = response;
    return "";
  }
  *head = response.substr(0, end_of_head);
  return response.substr(end_of_head + 4);
}

}  // namespace fusion::testing
