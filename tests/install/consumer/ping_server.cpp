// ping_server HOST PORT: one PING through the installed client library; prints the nonce back.
#include <segmatch/api/client.h>

#include <cstdio>
#include <cstdlib>

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: ping_server HOST PORT\n");
    return 2;
  }
  try {
    segmatch::api::Client client(argv[1], static_cast<uint16_t>(std::atoi(argv[2])));
    std::printf("PONG %llu\n", static_cast<unsigned long long>(client.ping(42)));
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "ping_server: %s\n", e.what());
    return 1;
  }
}
