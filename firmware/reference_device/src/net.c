/*
 * net.c - loopback/Ethernet transports of SPEC 1.1.
 *
 * TCP command channel: a listening socket, up to MAX_CONNECTIONS connections at once
 * (SPEC 1.1 wants at least two, so a second host can ABORT or take over), each with its
 * own kit deframer (SPEC 4.1) and its own output buffer.  Sockets are non-blocking: the
 * control loop must never wait for a slow host.
 *
 * UDP telemetry: one socket bound to the command port's *number* on the listening
 * address (SPEC 1.1 "UDP source"), so the host can tell the device's datagrams from
 * anybody else's.  One frame per datagram: allowed by SPEC 1.1 and the simplest.
 */
#define _POSIX_C_SOURCE 200809L

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "device.h"

static int set_nonblocking(int fd)
{
    int flags = fcntl(fd, F_GETFL, 0);
    return flags < 0 ? -1 : fcntl(fd, F_SETFL, flags | O_NONBLOCK);
}

int net_open(const char *host, uint16_t port)
{
    struct sockaddr_in a;
    socklen_t alen = sizeof a;
    int one = 1;
    int i;

    for (i = 0; i < MAX_CONNECTIONS; i++) {
        dev.conn[i].fd = -1;
    }
    memset(&a, 0, sizeof a);
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    if (inet_pton(AF_INET, host, &a.sin_addr) != 1) {
        fprintf(stderr, "hfb_reference_device: --host %s is not an IPv4 address\n", host);
        return -1;
    }
    dev.listen_fd = socket(AF_INET, SOCK_STREAM, 0);
    if (dev.listen_fd < 0) {
        perror("socket");
        return -1;
    }
    (void)setsockopt(dev.listen_fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (bind(dev.listen_fd, (struct sockaddr *)&a, sizeof a) != 0 || listen(dev.listen_fd, 8) != 0) {
        perror("bind/listen (tcp)");
        return -1;
    }
    if (getsockname(dev.listen_fd, (struct sockaddr *)&a, &alen) != 0) {
        perror("getsockname");
        return -1;
    }
    dev.local_ip = a.sin_addr.s_addr;
    dev.local_port = ntohs(a.sin_port);
    (void)set_nonblocking(dev.listen_fd);

    /* the telemetry source: same address, same port number, UDP (SPEC 1.1) */
    dev.udp_fd = socket(AF_INET, SOCK_DGRAM, 0);
    if (dev.udp_fd < 0 || bind(dev.udp_fd, (struct sockaddr *)&a, sizeof a) != 0) {
        perror("bind (udp, the command port's number)");
        return -1;
    }
    (void)set_nonblocking(dev.udp_fd);
    return 0;
}

static void accept_new(void)
{
    for (;;) {
        struct sockaddr_in peer;
        socklen_t plen = sizeof peer;
        int one = 1;
        int fd = accept(dev.listen_fd, (struct sockaddr *)&peer, &plen);
        int i;
        if (fd < 0) {
            return;                                  /* EAGAIN: nobody else waiting */
        }
        for (i = 0; i < MAX_CONNECTIONS && dev.conn[i].fd >= 0; i++) {
        }
        if (i == MAX_CONNECTIONS) {
            close(fd);                               /* full: the host sees a closed socket */
            continue;
        }
        (void)set_nonblocking(fd);
        /* responses are small and latency matters more than packing (SPEC 5.5 RTT) */
        (void)setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        dev.conn[i].fd = fd;
        dev.conn[i].serial = ++dev.next_connection_serial;
        dev.conn[i].peer_ip = peer.sin_addr.s_addr;
        dev.conn[i].peer_port = ntohs(peer.sin_port);
        dev.conn[i].out_len = 0;
        /* the deframer's context is the slot number, so replies go back where the
           command came from (SPEC 1.1) */
        hfb_deframer_init(&dev.conn[i].rx, commands_on_frame, (void *)&dev.conn[i]);
        /* and frames of another major version too: a CONNECT among them gets its
           DICTIONARY_MISMATCH (SPEC 7) */
        hfb_deframer_on_other_version(&dev.conn[i].rx, commands_on_other_version);
    }
}

static void flush(int c)
{
    connection_t *k = &dev.conn[c];
    while (k->fd >= 0 && k->out_len > 0) {
        ssize_t w = send(k->fd, k->out, k->out_len, MSG_NOSIGNAL);
        if (w < 0) {
            if (errno == EAGAIN || errno == EWOULDBLOCK) {
                return;
            }
            net_drop_connection(c);
            return;
        }
        memmove(k->out, k->out + w, k->out_len - (size_t)w);
        k->out_len -= (size_t)w;
    }
}

void net_drop_connection(int c)
{
    connection_t *k = &dev.conn[c];
    if (k->fd < 0) {
        return;
    }
    close(k->fd);
    k->fd = -1;
    k->out_len = 0;
    session_connection_closed(c);                    /* SPEC 7: the owner's close ends the session */
}

void net_poll(void)
{
    uint8_t buf[4096];
    int c;
    accept_new();
    for (c = 0; c < MAX_CONNECTIONS; c++) {
        connection_t *k = &dev.conn[c];
        while (k->fd >= 0) {
            ssize_t r = recv(k->fd, buf, sizeof buf, 0);
            if (r > 0) {
                hfb_deframer_feed(&k->rx, buf, (size_t)r);   /* executes the commands found */
            } else if (r == 0 || (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)) {
                net_drop_connection(c);
            } else {
                break;
            }
        }
        flush(c);
    }
}

int net_send_tcp(int c, const uint8_t *frame, size_t n)
{
    connection_t *k;
    if (c < 0 || c >= MAX_CONNECTIONS || dev.conn[c].fd < 0) {
        return -1;
    }
    k = &dev.conn[c];
    if (k->out_len + n > sizeof k->out) {
        flush(c);
        if (k->fd < 0 || k->out_len + n > sizeof k->out) {
            return -1;                               /* whole frames only, never a part */
        }
    }
    memcpy(k->out + k->out_len, frame, n);
    k->out_len += n;
    return 0;
}

int net_send_telemetry(const uint8_t *frame, size_t n)
{
    struct sockaddr_in to;
    if (dev.token == 0u || dev.owner < 0) {
        return -1;                                   /* SPEC 1.3: no session, no telemetry */
    }
    if (dev.telemetry_port == 0u) {
        return net_send_tcp(dev.owner, frame, n);    /* SPEC 1.1: telemetry_port = 0 */
    }
    memset(&to, 0, sizeof to);
    to.sin_family = AF_INET;
    to.sin_addr.s_addr = dev.conn[dev.owner].peer_ip;
    to.sin_port = htons(dev.telemetry_port);
    return sendto(dev.udp_fd, frame, n, 0, (struct sockaddr *)&to, sizeof to) == (ssize_t)n ? 0 : -1;
}

void net_close_all(void)
{
    int c;
    for (c = 0; c < MAX_CONNECTIONS; c++) {
        if (dev.conn[c].fd >= 0) {
            flush(c);
            close(dev.conn[c].fd);
            dev.conn[c].fd = -1;
        }
    }
    if (dev.listen_fd >= 0) {
        close(dev.listen_fd);
    }
    if (dev.udp_fd >= 0) {
        close(dev.udp_fd);
    }
}
