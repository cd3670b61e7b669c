#pragma once
/// \file
/// What kelvin says when the process crashes (SIGSEGV, SIGBUS, SIGFPE, SIGILL):
/// which plugin call was running, at which element, and where the work done so far
/// is. A plugin runs in kelvin's process, so its crash ends the run; everything a
/// command saves as it goes (the fit's state after each evaluation, say) is kept.

namespace kelvin {

/// Marks the calling thread as inside a plugin's evaluation (`who` must outlive the
/// call), and its end. Two stores: cheap enough for every material point.
void enter_plugin_call(const char* who, int element);
void leave_plugin_call();

/// Installs the crash handler once; `hint` (copied, truncated to 1 KiB) is printed
/// after the crash report, e.g. how to resume. Call again to change the hint.
void report_crashes(const char* hint);

}  // namespace kelvin
