#include "materials/crash_report.hpp"

#include <unistd.h>

#include <csignal>
#include <cstring>
#include <vector>

namespace kelvin {
namespace {

struct PluginCall {
  const char* who = nullptr;
  int element = -1;
};
thread_local PluginCall t_call;

char g_hint[1024] = "";

/// Appends to a fixed buffer without allocating: the handler may only do this.
struct Line {
  char text[2048];
  size_t size = 0;
  void add(const char* s) {
    while (*s && size + 1 < sizeof text) text[size++] = *s++;
  }
  void add(long v) {
    char digits[24];
    int n = 0;
    const bool negative = v < 0;
    unsigned long u =
        negative ? 0UL - static_cast<unsigned long>(v) : static_cast<unsigned long>(v);
    do {
      digits[n++] = static_cast<char>('0' + u % 10);
      u /= 10;
    } while (u && n < 23);
    if (negative) add("-");
    while (n) {
      const char c[2] = {digits[--n], '\0'};
      add(c);
    }
  }
};

const char* signal_name(int sig) {
  switch (sig) {
    case SIGSEGV:
      return "segmentation fault";
    case SIGBUS:
      return "bus error";
    case SIGFPE:
      return "arithmetic exception";
    case SIGILL:
      return "illegal instruction";
    default:
      return "fatal signal";
  }
}

void on_crash(int sig) {
  Line line;
  line.add("kelvin: crashed (");
  line.add(signal_name(sig));
  line.add(")");
  if (t_call.who) {
    line.add(" inside ");
    line.add(t_call.who);
    line.add(" at element ");
    line.add(static_cast<long>(t_call.element));
    line.add(": the plugin has a bug (kelvin check-material runs it alone)");
  } else {
    line.add(": a bug in kelvin; please report it with the scenario");
  }
  line.add("\n");
  if (g_hint[0]) {
    line.add(g_hint);
    line.add("\n");
  }
  [[maybe_unused]] const ssize_t written = ::write(STDERR_FILENO, line.text, line.size);
  // The default action (termination, a core file where enabled) follows on return.
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

}  // namespace

void enter_plugin_call(const char* who, int element) {
  t_call.who = who;
  t_call.element = element;
}

void leave_plugin_call() {
  t_call.who = nullptr;
}

void report_crashes(const char* hint) {
  std::strncpy(g_hint, hint, sizeof g_hint - 1);
  static bool installed = false;
  if (installed) return;
  installed = true;
  // Its own stack, so that a stack overflow can still be reported.
  static std::vector<char> stack(1 << 16);
  stack_t ss{};
  ss.ss_sp = stack.data();
  ss.ss_size = stack.size();
  sigaltstack(&ss, nullptr);
  struct sigaction sa {};
  sa.sa_handler = on_crash;
  sa.sa_flags = SA_ONSTACK | SA_RESETHAND | SA_NODEFER;
  sigemptyset(&sa.sa_mask);
  for (const int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL}) sigaction(sig, &sa, nullptr);
}

}  // namespace kelvin
