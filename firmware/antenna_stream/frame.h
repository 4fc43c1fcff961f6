/* The wire frame, shared by the firmware and the host-side test (see snn_antenna/bridge/protocol.py).
 *
 * payload (little-endian): seq u16, x u16, y u16; then crc u16 = CRC-16/XMODEM of those 6 bytes.
 * The 8 bytes are COBS-encoded (9 bytes, no zero inside) and followed by one 0x00 delimiter.
 *
 * The boot frame, sent once at reset: "BOOT", protocol version u8, reset cause u8 (MCUSR),
 * first seq u16, then the CRC of those 8 bytes; COBS-encoded (11 bytes) and delimited: a length
 * no sample frame has, so the host tells a new board session from a gap in the count.
 */
#ifndef ANTENNA_FRAME_H
#define ANTENNA_FRAME_H

#include <stdint.h>

#define FRAME_PAYLOAD_LEN 8u
#define FRAME_WIRE_LEN (FRAME_PAYLOAD_LEN + 2u) /* COBS overhead byte + delimiter */

uint16_t frame_crc16_xmodem(const uint8_t *data, uint8_t len);

/* COBS-encode len (< 254) bytes into out (len + 1 bytes); returns the encoded length. */
uint8_t frame_cobs_encode(const uint8_t *data, uint8_t len, uint8_t *out);

/* Build the complete wire frame, delimiter included; returns FRAME_WIRE_LEN. */
uint8_t frame_encode(uint16_t seq, uint16_t x, uint16_t y, uint8_t out[FRAME_WIRE_LEN]);

#define BOOT_PAYLOAD_LEN 10u
#define BOOT_WIRE_LEN (BOOT_PAYLOAD_LEN + 2u)
#define PROTOCOL_VERSION 1u

/* Build the boot frame, delimiter included; returns BOOT_WIRE_LEN. */
uint8_t frame_encode_boot(uint8_t cause, uint16_t first_seq, uint8_t out[BOOT_WIRE_LEN]);

#endif
