/* Preloaded into mpirun on a single-host run (coupler/protocol/mpi.py): a socket bound to the
 * wildcard address (0.0.0.0 or ::) is bound to loopback (127.0.0.1 or ::1) instead. Open MPI
 * 4.1's mpirun binds its out-of-band listener to the wildcard address whatever
 * oob_tcp_if_include says; everything else it does already goes over loopback. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <netinet/in.h>
#include <string.h>
#include <sys/socket.h>

typedef int (*bind_function)(int, const struct sockaddr *, socklen_t);

int bind(int fd, const struct sockaddr *address, socklen_t length) {
    static bind_function next_bind;
    if (!next_bind) next_bind = (bind_function)dlsym(RTLD_NEXT, "bind");
    if (!next_bind) {
        errno = ENOSYS;
        return -1;
    }
    if (address && address->sa_family == AF_INET && length >= sizeof(struct sockaddr_in)) {
        struct sockaddr_in ipv4;
        memcpy(&ipv4, address, sizeof ipv4);
        if (ipv4.sin_addr.s_addr == htonl(INADDR_ANY)) {
            ipv4.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
            return next_bind(fd, (const struct sockaddr *)&ipv4, sizeof ipv4);
        }
    } else if (address && address->sa_family == AF_INET6 && length >= sizeof(struct sockaddr_in6)) {
        struct sockaddr_in6 ipv6;
        memcpy(&ipv6, address, sizeof ipv6);
        if (IN6_IS_ADDR_UNSPECIFIED(&ipv6.sin6_addr)) {
            ipv6.sin6_addr = in6addr_loopback;
            return next_bind(fd, (const struct sockaddr *)&ipv6, sizeof ipv6);
        }
    }
    return next_bind(fd, address, length);
}
