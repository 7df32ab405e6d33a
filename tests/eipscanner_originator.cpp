// A Class 1 originator for the CM1 EtherNet/IP module, written on EIPScanner's public API
// (tests/test_eipscanner.py builds it against an installed EIPScanner and runs it).
//
//   eipscanner_originator HOST PORT TARGET
//
// cm1-ethernetip-interface-manual.txt ch. 4: Forward_Open to the assemblies 0x80
// (configuration), 0x66 (output, 14 bytes, O->T with the 32-bit run/idle header) and 0x65
// (input, 8 bytes, T->O) at RPI 10 ms; 3.2: the output image with P0 = TARGET, then the
// control word 1 (start); 3.1: the status through T->O until in position at TARGET;
// Forward_Close; then the input assembly once more by explicit messaging.  Prints one
// line of JSON with what it saw.

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "ConnectionManager.h"
#include "MessageRouter.h"
#include "SessionInfo.h"
#include "cip/EPath.h"
#include "cip/Services.h"
#include "cip/connectionManager/ConnectionParameters.h"
#include "cip/connectionManager/NetworkConnectionParams.h"
#include "utils/Logger.h"

using eipScanner::ConnectionManager;
using eipScanner::MessageRouter;
using eipScanner::SessionInfo;
using eipScanner::cip::EPath;
using eipScanner::cip::GeneralStatusCodes;
using eipScanner::cip::ServiceCodes;
using eipScanner::cip::connectionManager::ConnectionParameters;
using eipScanner::cip::connectionManager::NetworkConnectionParams;
using eipScanner::utils::LogLevel;
using eipScanner::utils::Logger;
using Clock = std::chrono::steady_clock;

namespace {

constexpr std::uint32_t kRpiMicroseconds = 10000;  // RPI 10 ms (manual ch. 4)
constexpr std::uint16_t kOutputSize = 14;          // assembly 0x66 (3.2)
constexpr std::uint16_t kInputSize = 8;            // assembly 0x65 (3.1)

struct Status {
    std::uint16_t error = 0;
    std::uint16_t motor = 0;
    std::int32_t position = 0;
};

template <typename T>
void put(std::vector<std::uint8_t>& out, std::size_t at, T value) {
    for (std::size_t i = 0; i < sizeof(T); ++i) {
        out[at + i] = static_cast<std::uint8_t>(static_cast<std::uint64_t>(value) >> (8 * i));
    }
}

// 3.2: run flag, P0 (pulses), S0 (K37 unit), A0 (kpps^2), control word, K52 byte.
std::vector<std::uint8_t> outputImage(std::int32_t target, std::uint8_t control) {
    std::vector<std::uint8_t> out(kOutputSize, 0);
    put<std::uint16_t>(out, 0, 1);
    put<std::int32_t>(out, 2, target);
    put<std::int32_t>(out, 6, 100);
    put<std::int16_t>(out, 10, 100);
    out[12] = control;
    return out;
}

// 3.1: communication error code, motor status code, position (little endian).
Status inputImage(const std::vector<std::uint8_t>& data) {
    Status s;
    if (data.size() >= kInputSize) {
        s.error = static_cast<std::uint16_t>(data[0] | data[1] << 8);
        s.motor = static_cast<std::uint16_t>(data[2] | data[3] << 8);
        std::uint32_t raw = 0;
        for (int i = 3; i >= 0; --i) raw = raw << 8 | data[4 + i];
        s.position = static_cast<std::int32_t>(raw);
    }
    return s;
}

ConnectionParameters exclusiveOwner() {
    ConnectionParameters p;
    p.connectionPath = {0x20, 0x04, 0x24, 0x80, 0x2C, 0x66, 0x2C, 0x65};
    p.o2tRealTimeFormat = true;   // 32-bit run/idle header O->T (20 bytes with the count)
    p.t2oRealTimeFormat = false;  // modeless T->O (10 bytes with the count)
    p.originatorVendorId = 0x0586;
    p.originatorSerialNumber = 0x00C0FFEE;
    p.priorityTimeTick = 0x0A;
    p.timeoutTicks = 0xF0;
    p.connectionTimeoutMultiplier = 2;  // x16: 160 ms without O->T closes it
    p.o2tRPI = kRpiMicroseconds;
    p.t2oRPI = kRpiMicroseconds;
    p.o2tNetworkConnectionParams = NetworkConnectionParams::P2P |
                                   NetworkConnectionParams::SCHEDULED_PRIORITY | kOutputSize;
    p.t2oNetworkConnectionParams = NetworkConnectionParams::P2P |
                                   NetworkConnectionParams::SCHEDULED_PRIORITY | kInputSize;
    p.transportTypeTrigger = NetworkConnectionParams::CLASS1;  // cyclic
    return p;
}

std::string statusJson(const Status& s) {
    std::ostringstream os;
    os << "[" << s.error << "," << s.motor << "," << s.position << "]";
    return os.str();
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 4) {
        std::cerr << "usage: " << argv[0] << " HOST PORT TARGET\n";
        return 2;
    }
    const std::string host = argv[1];
    const int port = std::atoi(argv[2]);
    const std::int32_t target = std::atoi(argv[3]);
    Logger::setLogLevel(LogLevel::WARNING);

    auto si = std::make_shared<SessionInfo>(host, port);
    ConnectionManager manager;
    auto io = manager.forwardOpen(si, exclusiveOwner());
    auto connection = io.lock();
    if (!connection) {
        std::cout << "{\"opened\": false}" << std::endl;
        return 1;
    }

    std::vector<Status> seen;
    std::vector<std::uint16_t> counts;
    std::vector<double> arrivals;
    bool closedByTimeout = false;
    const auto start = Clock::now();
    connection->setDataToSend(outputImage(target, 0));
    connection->setReceiveDataListener(
        [&](std::uint32_t, std::uint16_t count, const std::vector<std::uint8_t>& data) {
            seen.push_back(inputImage(data));
            counts.push_back(count);
            arrivals.push_back(std::chrono::duration<double>(Clock::now() - start).count());
        });
    connection->setCloseListener([&]() { closedByTimeout = true; });

    bool started = false;
    double inPositionAt = -1;
    const auto deadline = start + std::chrono::seconds(15);
    while (manager.hasOpenConnections() && Clock::now() < deadline) {
        manager.handleConnections(std::chrono::milliseconds(1));
        const double now = std::chrono::duration<double>(Clock::now() - start).count();
        if (!started && now > 0.2) {  // the profile first, then the control word 0 -> 1
            connection->setDataToSend(outputImage(target, 1));
            started = true;
        }
        if (started && inPositionAt < 0 && !seen.empty() && seen.back().motor == 8 &&
            seen.back().position == target) {
            inPositionAt = now;
        }
        if (inPositionAt >= 0 && now > inPositionAt + 0.3) break;  // some cycles at rest
    }
    const bool open = manager.hasOpenConnections();
    if (open) manager.forwardClose(si, io);

    MessageRouter router;
    auto reply = router.sendRequest(si, ServiceCodes::GET_ATTRIBUTE_SINGLE, EPath(4, 0x65, 3));
    const bool readOk = reply.getGeneralStatusCode() == GeneralStatusCodes::SUCCESS;

    bool sawRunning = false;
    for (const auto& s : seen) sawRunning = sawRunning || (s.motor == 0);
    std::vector<double> gaps;
    for (std::size_t i = 1; i < arrivals.size(); ++i) gaps.push_back(arrivals[i] - arrivals[i - 1]);
    std::sort(gaps.begin(), gaps.end());
    const double median = gaps.empty() ? 0.0 : gaps[gaps.size() / 2];
    bool countsStep = true;
    for (std::size_t i = 1; i < counts.size(); ++i) {
        countsStep = countsStep && static_cast<std::uint16_t>(counts[i] - counts[i - 1]) == 1;
    }

    std::cout << "{\"opened\": true, \"open_until_close\": " << (open ? "true" : "false")
              << ", \"timed_out\": " << (closedByTimeout ? "true" : "false")
              << ", \"received\": " << seen.size()
              << ", \"saw_running\": " << (sawRunning ? "true" : "false")
              << ", \"in_position_after_s\": " << inPositionAt
              << ", \"last\": " << (seen.empty() ? "null" : statusJson(seen.back()))
              << ", \"counts_step_by_one\": " << (countsStep ? "true" : "false")
              << ", \"median_interval_ms\": " << median * 1000.0
              << ", \"explicit_ok\": " << (readOk ? "true" : "false")
              << ", \"explicit\": " << (readOk ? statusJson(inputImage(reply.getData())) : "null")
              << "}" << std::endl;
    return 0;
}
