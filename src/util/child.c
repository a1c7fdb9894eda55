/* Stoppable work in a forked child (child.h). */
#include "util/child.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <stdint.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include "util/fsutil.h"
#include "util/stop.h"

/* What the child sends back through the pipe, then out_size bytes. */
typedef struct answer {
    int rc;
    vx_err err;
} answer;

static void reap(pid_t pid, int *status)
{
    *status = 0;
    while (waitpid(pid, status, 0) < 0 && errno == EINTR) {
    }
}

static void *reaper(void *arg)
{
    int status;
    reap((pid_t)(intptr_t)arg, &status);
    return NULL;
}

/* A killed child with gigabytes mapped takes the kernel 100 ms or more to
 * tear down: the caller need not wait for that, a detached thread reaps
 * it (or this one, when no thread can be made). */
static void reap_later(pid_t pid)
{
    pthread_attr_t a;
    pthread_t t;
    int ok = 0;
    if (pthread_attr_init(&a) == 0) {
        ok = pthread_attr_setdetachstate(&a, PTHREAD_CREATE_DETACHED) == 0 &&
             pthread_create(&t, &a, reaper, (void *)(intptr_t)pid) == 0;
        pthread_attr_destroy(&a);
    }
    if (!ok) reaper((void *)(intptr_t)pid);
}

static void child_main(int fd, pid_t parent, vx_child_fn fn, void *ud, void *out, size_t out_size)
{
    /* The daemon blocks its shutdown signals in every thread; the child
     * takes them the default way (a unit's stop kills it at once). */
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, NULL);
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(1); /* the parent died before prctl */
    /* The calling thread's stop hook reads the parent's job state under
     * its locks, which another thread may have held at the fork: in the
     * child it would wait forever. The parent polls and kills the child. */
    vx_stop_set(NULL, NULL);
    answer a;
    memset(&a, 0, sizeof a);
    a.rc = fn(ud, out, out_size, &a.err) == 0 ? 0 : -1;
    if (vx_write_all(fd, &a, sizeof a) ||
        (a.rc == 0 && out_size && vx_write_all(fd, out, out_size)))
        _exit(1);
    _exit(0);
}

int vx_child_call(vx_child_fn fn, void *ud, void *out, size_t out_size, vx_child_poll poll_fn,
                  void *poll_ud, int poll_ms, vx_err *err)
{
    int fds[2];
    if (pipe2(fds, O_CLOEXEC))
        return vx_err_set(err, VX_EINTERNAL, "child_failed", "cannot make a pipe: %s",
                          strerror(errno));
    pid_t parent = getpid();
    pid_t pid = fork();
    if (pid < 0) {
        int e = errno;
        close(fds[0]);
        close(fds[1]);
        return vx_err_set(err, VX_EINTERNAL, "child_failed", "cannot fork: %s", strerror(e));
    }
    if (pid == 0) {
        close(fds[0]);
        child_main(fds[1], parent, fn, ud, out, out_size);
    }
    close(fds[1]);

    answer a;
    size_t total = sizeof a + out_size, got = 0;
    int rc = -1, status;
    for (;;) {
        struct pollfd pf = {.fd = fds[0], .events = POLLIN};
        int n = poll(&pf, 1, poll_ms);
        if (n < 0 && errno != EINTR) {
            vx_err_set(err, VX_EINTERNAL, "child_failed", "poll: %s", strerror(errno));
            goto kill_child;
        }
        if (n > 0) {
            ssize_t k;
            if (got < sizeof a)
                k = read(fds[0], (char *)&a + got, sizeof a - got);
            else
                k = read(fds[0], (char *)out + (got - sizeof a), total - got);
            if (k < 0 && errno == EINTR) continue;
            if (k <= 0) break; /* end of file: the child has gone */
            got += (size_t)k;
            if (got >= sizeof a && (a.rc != 0 || got == total)) break;
            continue; /* more to read: no poll between pieces of the answer */
        }
        if (poll_fn && poll_fn(poll_ud, err)) goto kill_child;
    }
    close(fds[0]);
    reap(pid, &status);
    if (got >= sizeof a && a.rc != 0) {
        if (err) *err = a.err;
        return -1;
    }
    if (got == total) return 0;
    /* Died without an answer: a stop that raced with it (SIGTERM of the
     * whole unit) says why; otherwise the kernel's OOM killer or a crash. */
    if (poll_fn && poll_fn(poll_ud, err)) return -1;
    if (WIFSIGNALED(status)) {
        int sig = WTERMSIG(status);
        /* SIGKILL from outside: the kernel's OOM killer as a rule; any
         * other signal is the work's own crash */
        return vx_err_set(err, VX_EINTERNAL, "child_failed",
                          "the worker process was killed by signal %d (%s%s)", sig, strsignal(sig),
                          sig == SIGKILL ? ": out of memory?" : ": a crash");
    }
    return vx_err_set(err, VX_EINTERNAL, "child_failed",
                      "the worker process exited (status %d) without an answer",
                      WIFEXITED(status) ? WEXITSTATUS(status) : -1);
kill_child:
    kill(pid, SIGKILL);
    close(fds[0]);
    reap_later(pid);
    return rc;
}
