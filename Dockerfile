# voxeld image: headless OpenGL (EGL) mesh service, and voxelctl.
#
#   docker build -t voxeld .        (podman: podman build --format docker -t voxeld .,
#                                    else podman drops the HEALTHCHECK)
#   GPU:  docker run --gpus all -e NVIDIA_DRIVER_CAPABILITIES=graphics,compute,utility \
#           -p 8080:8080 -v voxeld-data:/var/lib/voxeld voxeld
#   CPU:  docker run -p 8080:8080 -v voxeld-data:/var/lib/voxeld voxeld   (Mesa llvmpipe)
#   more options: docker run ... voxeld --max-queued-jobs 16   (the ENTRYPOINT keeps
#                 --listen 0.0.0.0:8080 --data-dir /var/lib/voxeld; a flag given again wins)
#   or VOXELD_* variables: docker run -e VOXELD_JOB_TIMEOUT=120 ...
#
# Both stages use the full debian:bookworm image (not -slim): it is the one
# image that tests/deploy/test_container.sh can build offline (debootstrap).
ARG BASE=debian:bookworm

# ---- build -------------------------------------------------------------------
FROM ${BASE} AS build
ARG JOBS=2
ENV DEBIAN_FRONTEND=noninteractive
# The build subset of scripts/install-deps.sh (no tests, benchmarks, podman).
RUN apt-get update -qq \
 && apt-get install -y -qq --no-install-recommends \
      build-essential cmake pkg-config \
      libegl-dev libgl-dev libopengl-dev \
      libmicrohttpd-dev libcjson-dev libdraco-dev libtinygltf-dev nlohmann-json3-dev libeigen3-dev \
      libopenvdb-dev libboost-dev libboost-iostreams-dev libtbb-dev libimath-dev \
      libblosc-dev zlib1g-dev libzstd-dev \
      libfftw3-dev libosd-dev libpng-dev libsystemd-dev nettle-dev libcurl4-openssl-dev libpq-dev \
 && rm -rf /var/lib/apt/lists/*
WORKDIR /src
COPY . .
# Only the daemon and the client: no tests, no benchmarks.
RUN cmake -S . -B /build -DCMAKE_BUILD_TYPE=Release -DVX_TESTS=OFF -DVX_BENCH=OFF \
 && cmake --build /build -j"${JOBS}" --target voxeld voxelctl \
 && strip /build/voxeld /build/voxelctl \
 && /build/voxeld --version && /build/voxelctl --version
# The runtime packages of every shared library voxeld links, whatever the
# engines link by then: ldd -> owning package (a safety net for the explicit
# list below). /lib and /usr/lib are the same directory (merged /usr), but
# dpkg knows each file under one of the two names only.
RUN set -e; for lib in $(ldd /build/voxeld /build/voxelctl | awk '$2 == "=>" && $3 ~ /^\// {print $3}'); do \
      real=$(readlink -f "$lib"); \
      for f in "$lib" "$real" "/usr$real" "${real#/usr}"; do \
        if p=$(dpkg -S "$f" 2>/dev/null); then echo "${p%%:*}"; break; fi; \
      done; \
    done | sort -u >/build/runtime-packages \
 && cat /build/runtime-packages

# ---- runtime -------------------------------------------------------------------
FROM ${BASE}
ARG VERSION=0.1.0
LABEL org.opencontainers.image.title="voxeld" \
      org.opencontainers.image.description="Headless OpenGL mesh service: voxel grids, renders, Gregory and Catmull-Clark meshes over HTTP/JSON" \
      org.opencontainers.image.version="${VERSION}" \
      org.opencontainers.image.licenses="GPL-3.0-or-later" \
      org.opencontainers.image.documentation="README.md, voxeld(8), voxelctl(1)"
ENV DEBIAN_FRONTEND=noninteractive
COPY --from=build /build/runtime-packages /tmp/runtime-packages
# libegl-mesa0 + libgl1-mesa-dri: Mesa's EGL and llvmpipe, the CPU fallback
# (dlopened by libglvnd, so ldd does not see them). OpenVDB, FFTW and
# OpenSubdiv are listed as well as found by ldd. curl: the HEALTHCHECK
# (its libcurl4 is also voxelctl's). ca-certificates: libcurl's TLS to an
# https:// S3 endpoint (libcurl4 only recommends it: a cluster-mode pod
# could not reach its bucket, curl error 77).
RUN apt-get update -qq \
 && apt-get install -y -qq --no-install-recommends \
      libmicrohttpd12 libcjson1 libdraco7 libpng16-16 libsystemd0 libnettle8 libzstd1 libpq5 \
      libegl1 libopengl0 libgl1 libegl-mesa0 libgl1-mesa-dri \
      libfftw3-single3 libfftw3-double3 libopenvdb10.0 libosdcpu3.5.0 \
      curl ca-certificates \
      $(cat /tmp/runtime-packages) \
 && rm -rf /var/lib/apt/lists/* /tmp/runtime-packages

# NVIDIA through glvnd: the NVIDIA container toolkit mounts libEGL_nvidia.so.0
# and the driver when NVIDIA_DRIVER_CAPABILITIES includes graphics; this
# vendor file makes libglvnd's libEGL load it (EGL device platform).
RUN mkdir -p /usr/share/glvnd/egl_vendor.d \
 && printf '%s\n' '{"file_format_version":"1.0.0","ICD":{"library_path":"libEGL_nvidia.so.0"}}' \
      >/usr/share/glvnd/egl_vendor.d/10_nvidia.json
ENV NVIDIA_VISIBLE_DEVICES=all \
    NVIDIA_DRIVER_CAPABILITIES=graphics,compute,utility

# Non-root user; video/render give access to /dev/dri render nodes that a
# runtime passes in (--device /dev/dri) when their gids are the host's:
# video's (44) is Debian's everywhere, render's is the host's own, so give
# it with --group-add (README). Debian's base image may lack render.
RUN getent group render >/dev/null || groupadd --system render \
 && groupadd --gid 10001 voxeld \
 && useradd --uid 10001 --gid 10001 --groups video,render --no-log-init \
      --home-dir /var/lib/voxeld --no-create-home --shell /usr/sbin/nologin voxeld \
 && install -d -o voxeld -g voxeld -m 0750 /var/lib/voxeld

COPY --from=build /build/voxeld /build/voxelctl /usr/bin/

USER voxeld
WORKDIR /var/lib/voxeld
VOLUME /var/lib/voxeld
EXPOSE 8080
HEALTHCHECK --interval=30s --timeout=5s --start-period=60s --retries=3 \
  CMD curl -fsS -o /dev/null http://127.0.0.1:8080/readyz || exit 1
# SIGTERM (docker stop) is a graceful stop: exit 0.
STOPSIGNAL SIGTERM
# The defaults live in the ENTRYPOINT, so that arguments given to the image
# (CMD) add to them: `docker run voxeld --job-timeout 60` still listens on
# 0.0.0.0:8080 with its data in /var/lib/voxeld. A flag given again wins.
ENTRYPOINT ["voxeld", "--listen", "0.0.0.0:8080", "--data-dir", "/var/lib/voxeld"]
CMD []
