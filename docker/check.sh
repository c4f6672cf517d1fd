#!/usr/bin/env bash
# The image builds and serves: build it (on a Debian-made base where the public registry is out
# of reach), start an API and a worker container on a shared volume, calibrate a rendered clip
# through the API, then ask /project. Run by hand (minutes), not in .ci/run:
#
#   make docker-check            (or docker/check.sh; needs Docker Engine: Debian's docker.io)
#
# Environment: BASE_IMAGE (default: squashcal-base:bookworm, made by docker/base-image.sh when
# missing), IMAGE (default squashcal:check), PORT (default 18000), KEEP=1 leaves the containers.
set -euo pipefail
cd "$(dirname "$0")/.."

BASE_IMAGE="${BASE_IMAGE:-squashcal-base:bookworm}"
IMAGE="${IMAGE:-squashcal:check}"
PORT="${PORT:-18000}"
NAME="squashcal-check-$$"

log() { printf '\n== %s\n' "$*"; }

pip_setting() {
    # an environment variable wins over pip's configuration files, as in pip itself
    local env_name="$1" key="$2"
    if [ -n "${!env_name:-}" ]; then echo "${!env_name}"; return; fi
    python3 -m pip config get "$key" 2>/dev/null || true
}

stage_pip_settings() {
    # the index and CA bundle this machine's pip uses, for the build stage (docker/pip/README.md)
    rm -f docker/pip/pip.conf docker/pip/ca.crt
    local index cert
    index=$(pip_setting PIP_INDEX_URL global.index-url)
    cert=$(pip_setting PIP_CERT global.cert)
    if [ -n "$index" ]; then
        printf '[global]\nindex-url = %s\n' "$index" >docker/pip/pip.conf
        echo "pip index for the build: $index"
    fi
    if [ -n "$cert" ] && [ -f "$cert" ]; then
        cp "$cert" docker/pip/ca.crt
        echo "pip CA bundle for the build: $cert"
    fi
}

build_image() {
    if ! docker image inspect "$BASE_IMAGE" >/dev/null 2>&1; then
        if [ "$BASE_IMAGE" = squashcal-base:bookworm ]; then
            log "base image: debootstrap (a few minutes)"
            docker/base-image.sh "$BASE_IMAGE"
        else
            docker pull "$BASE_IMAGE"
        fi
    fi
    stage_pip_settings
    log "build $IMAGE on $BASE_IMAGE"
    local began=$SECONDS
    docker build -f docker/Dockerfile --build-arg BASE_IMAGE="$BASE_IMAGE" -t "$IMAGE" .
    echo "image built in $((SECONDS - began)) s"
}

json_field() { python3 -c 'import json, sys; print(json.load(sys.stdin)'"$1"')'; }

cleanup() {
    if [ "${KEEP:-0}" = 1 ]; then
        echo "kept: containers $NAME-api $NAME-worker, volume $NAME-data"
        return
    fi
    docker rm -f "$NAME-api" "$NAME-worker" >/dev/null 2>&1 || true
    docker volume rm "$NAME-data" >/dev/null 2>&1 || true
}

wait_for() {
    # wait_for SECONDS DESCRIPTION COMMAND...: retry COMMAND every 0.2 s
    local limit=$1 what=$2 began=$SECONDS
    shift 2
    until "$@" >/dev/null 2>&1; do
        if ((SECONDS - began > limit)); then
            echo "timed out waiting for $what" >&2
            docker logs "$NAME-api" 2>&1 | tail -20 >&2 || true
            docker logs "$NAME-worker" 2>&1 | tail -20 >&2 || true
            exit 1
        fi
        sleep 0.2
    done
}

api_ready() { [ "$(curl -s -o /dev/null -w '%{http_code}' "$URL/readyz")" = 200 ]; }
worker_polling() { docker logs "$NAME-worker" 2>&1 | grep -q ' polling '; }

start_containers() {
    log "start api and worker containers (volume $NAME-data, API on 127.0.0.1:$PORT)"
    docker volume create "$NAME-data" >/dev/null
    local began=$SECONDS
    # the image's default command: migrate, then serve
    docker run -d --name "$NAME-api" -v "$NAME-data:/data" -p "127.0.0.1:$PORT:8000" "$IMAGE" >/dev/null
    wait_for 300 "the API's /readyz" api_ready
    echo "API ready (migrated, kernels loaded) after $((SECONDS - began)) s"
    began=$SECONDS
    docker run -d --name "$NAME-worker" -v "$NAME-data:/data" "$IMAGE" squashcal worker >/dev/null
    wait_for 300 "the worker" worker_polling
    echo "worker polling (kernels loaded) after $((SECONDS - began)) s"
}

calibrate_demo_clip() {
    log "calibrate the demo clip through the API"
    KEY=$(docker exec "$NAME-api" squashcal keys create --name check | tail -1)
    AUTH="Authorization: Bearer $KEY"
    COURT=$(curl -sf -H "$AUTH" -H 'Content-Type: application/json' \
        -d '{"name": "docker check", "spec": "wsf"}' "$URL/courts" | json_field '["id"]')
    local clip
    clip=$(mktemp /tmp/squashcal-demo.XXXXXX.mp4)
    # rendered inside the API container by the service's own court renderer
    curl -sf -H "$AUTH" -o "$clip" "$URL/demo/clip.mp4"
    echo "demo clip: $(stat -c %s "$clip") bytes"
    local began=$SECONDS job status
    job=$(curl -sf -H "$AUTH" -F "files=@$clip;type=video/mp4" "$URL/courts/$COURT/calibrations" |
        json_field '["job_id"]')
    rm -f "$clip"
    while :; do
        status=$(curl -sf -H "$AUTH" "$URL/jobs/$job" | json_field '["status"]')
        case "$status" in
        succeeded) break ;;
        failed)
            curl -s -H "$AUTH" "$URL/jobs/$job"
            exit 1
            ;;
        esac
        if ((SECONDS - began > 600)); then
            echo "job $job still $status after 600 s" >&2
            exit 1
        fi
        sleep 0.5
    done
    echo "job $job succeeded in $((SECONDS - began)) s from the upload; its timings (s):"
    curl -sf -H "$AUTH" "$URL/jobs/$job" | json_field '["timings_s"]'
}

project_answers() {
    log "/project through the fitted camera"
    local body answer
    body="{\"court_id\": \"$COURT\", \"pixels\": [[640, 600], [0, 0]]}"
    answer=$(curl -sf -H "$AUTH" -H 'Content-Type: application/json' -w '\ntime_total %{time_total} s' \
        -d "$body" "$URL/project")
    echo "$answer"
    # the floor below the picture's lower middle must be found on the court
    echo "$answer" | head -1 | python3 -c 'import json, sys; r = json.load(sys.stdin); \
        assert r["points"][0] is not None and r["inside_court"][0], r; print("ok: /project answers")'
}

main() {
    command -v docker >/dev/null || { echo "docker is missing: apt-get install -y docker.io" >&2; exit 1; }
    URL="http://127.0.0.1:$PORT"
    trap cleanup EXIT
    build_image
    start_containers
    calibrate_demo_clip
    project_answers
    log "docker check passed"
}

main "$@"
