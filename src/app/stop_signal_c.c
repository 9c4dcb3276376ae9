/* SIGTERM (and SIGUSR1) as a request to stop a load history after its
   current step: the handler only sets a flag that the history polls. */
#include <signal.h>
#include <string.h>

static volatile sig_atomic_t fc_stop_flag = 0;

static void fc_stop_handler(int sig) {
  (void)sig;
  fc_stop_flag = 1;
}

void fc_stop_signal_install(void) {
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = fc_stop_handler;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGTERM, &sa, NULL);
  sigaction(SIGUSR1, &sa, NULL);
}

int fc_stop_signal_requested(void) { return fc_stop_flag ? 1 : 0; }
