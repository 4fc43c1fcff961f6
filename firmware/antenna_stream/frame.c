#include "frame.h"

#ifdef __AVR__
#include <util/crc16.h>
#define crc_xmodem_update _crc_xmodem_update
#else
/* The C equivalent that avr-libc documents for _crc_xmodem_update (poly 0x1021, MSB first). */
static uint16_t crc_xmodem_update(uint16_t crc, uint8_t data)
{
    crc ^= (uint16_t)data << 8;
    for (uint8_t i = 0; i < 8; i++)
        crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    return crc;
}
#endif

uint16_t frame_crc16_xmodem(const uint8_t *data, uint8_t len)
{
    uint16_t crc = 0; /* XMODEM starts from 0, as binascii.crc_hqx(data, 0) */
    while (len--)
        crc = crc_xmodem_update(crc, *data++);
    return crc;
}

uint8_t frame_cobs_encode(const uint8_t *data, uint8_t len, uint8_t *out)
{
    uint8_t code_at = 0, n = 1, code = 1;
    for (uint8_t i = 0; i < len; i++) {
        if (data[i] == 0) {
            out[code_at] = code;
            code_at = n++;
            code = 1;
        } else {
            out[n++] = data[i];
            code++;
        }
    }
    out[code_at] = code;
    return n;
}

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v & 0xffu);
    p[1] = (uint8_t)(v >> 8);
}

uint8_t frame_encode(uint16_t seq, uint16_t x, uint16_t y, uint8_t out[FRAME_WIRE_LEN])
{
    uint8_t payload[FRAME_PAYLOAD_LEN];
    put_u16(payload, seq);
    put_u16(payload + 2, x);
    put_u16(payload + 4, y);
    put_u16(payload + 6, frame_crc16_xmodem(payload, 6));
    uint8_t n = frame_cobs_encode(payload, FRAME_PAYLOAD_LEN, out);
    out[n++] = 0x00;
    return n;
}

uint8_t frame_encode_boot(uint8_t cause, uint16_t first_seq, uint8_t out[BOOT_WIRE_LEN])
{
    uint8_t payload[BOOT_PAYLOAD_LEN] = { 'B', 'O', 'O', 'T', PROTOCOL_VERSION, cause };
    put_u16(payload + 6, first_seq);
    put_u16(payload + 8, frame_crc16_xmodem(payload, 8));
    uint8_t n = frame_cobs_encode(payload, BOOT_PAYLOAD_LEN, out);
    out[n++] = 0x00;
    return n;
}
